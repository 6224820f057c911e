//! The NIF layer of RingTracer: a thin translation between Erlang terms and
//! `ring_tracer_kernel`. Nothing here renders; every function converts its
//! arguments, calls the kernel, and converts the answer back.
//!
//! Loaded by `RingTracer.Native` with `:erlang.load_nif/2`.

mod clock;
mod convert;
mod defaults;
mod fs;
mod image;
mod panic;
mod pixels;
mod scene;
mod trace;

rustler::init!("Elixir.RingTracer.Native", load = panic::load);
