//! What RingTracer's processes send each other compressed: an atom's pixels, from a
//! grandchild to the job's parent ([`pixels`]), and plain zstd frames ([`frames`], e.g. a
//! scene shipped to a node). The NIF (`RingTracer.Native`) wraps these functions; the pixels'
//! conversion to 8 bits is the kernel's, that of its PNG writer.

pub mod error;
pub mod frames;
pub mod pixels;

pub use error::Error;
pub use pixels::Format;
