//! Builds the project's Embree harness (`c/embree_side.c`) when Debian's `libembree-dev` headers
//! are installed, and sets `cfg(embree)`; without them the bench says so and times ours only.

use std::path::Path;

fn main() {
    println!("cargo::rustc-check-cfg=cfg(embree)");
    println!("cargo::rerun-if-changed=c/embree_side.c");
    println!("cargo::rerun-if-env-changed=EMBREE_INCLUDE");
    let include = std::env::var("EMBREE_INCLUDE").unwrap_or_else(|_| "/usr/include".into());
    // Installing libembree-dev later rebuilds the bench with Embree. A missing path reruns this
    // script on every build; once present, the directory is watched rather than the header,
    // because dpkg keeps the header's mtime from its packaging (older than any build here) but
    // the directory it creates has the time of the install.
    println!("cargo::rerun-if-changed={include}/embree3");
    if !Path::new(&include).join("embree3/rtcore.h").exists() {
        println!(
            "cargo::warning=Embree 3 headers not found ({include}/embree3/rtcore.h): \
             the bench times RingTracer only (apt-get install libembree-dev)"
        );
        return;
    }
    cc::Build::new()
        .file("c/embree_side.c")
        .include(&include)
        .opt_level(2)
        .compile("embree_side");
    println!("cargo::rustc-link-lib=embree3");
    println!("cargo::rustc-cfg=embree");
}
