//! What a panic in the kernel prints. Rustler turns the panic into an error
//! the Elixir caller sees (`RingTracer.Kernel.Native` reports it per atom);
//! the default hook would also print a full backtrace on the node's stderr
//! when `RUST_BACKTRACE` is set. One line is enough there.

use rustler::{Env, Term};

/// Installed when the library loads.
pub fn load(_env: Env, _info: Term) -> bool {
    std::panic::set_hook(Box::new(|info| {
        let place = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!(
            "ring_tracer NIF: panic{place}: {info_payload}",
            info_payload = payload(info)
        );
    }));
    true
}

fn payload(info: &std::panic::PanicHookInfo) -> String {
    if let Some(s) = info.payload().downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = info.payload().downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".to_string()
    }
}
