//! The frames between client and server: a 4-byte big-endian length, then
//! a tag byte and the data (Erlang's `{packet, 4}`).

use std::io::{self, Read, Write};

/// The largest frame either side sends (a line of output, an argument).
pub const MAX_FRAME: usize = 64 * 1024 * 1024;

/// Writes one frame of `tag` and `data`.
pub fn write(out: &mut impl Write, tag: u8, data: &[u8]) -> io::Result<()> {
    let len = u32::try_from(data.len() + 1)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "frame too large"))?;
    let mut buf = Vec::with_capacity(5 + data.len());
    buf.extend_from_slice(&len.to_be_bytes());
    buf.push(tag);
    buf.extend_from_slice(data);
    out.write_all(&buf)
}

/// Reads one frame: its tag and data; `None` at a clean end of stream.
pub fn read(input: &mut impl Read) -> io::Result<Option<(u8, Vec<u8>)>> {
    let mut len = [0u8; 4];
    match input.read_exact(&mut len) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Ok(None),
        Err(e) => return Err(e),
    }
    let len = u32::from_be_bytes(len) as usize;
    if len == 0 || len > MAX_FRAME {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("bad frame length {len}"),
        ));
    }
    // grown as the bytes arrive (never more than about twice what came), not allocated at
    // the declared length: a peer that declares 64 MiB and sends ten bytes costs ten
    let mut body = Vec::new();
    input.take(len as u64).read_to_end(&mut body)?;
    if body.len() < len {
        return Err(io::Error::new(
            io::ErrorKind::UnexpectedEof,
            format!("frame cut short: {} of {len} bytes", body.len()),
        ));
    }
    let data = body.split_off(1);
    Ok(Some((body[0], data)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip() {
        let mut buf = Vec::new();
        write(&mut buf, b'A', b"--width").unwrap();
        write(&mut buf, b'G', b"").unwrap();
        assert_eq!(&buf[..5], &[0, 0, 0, 8, b'A']);
        let mut input = &buf[..];
        assert_eq!(read(&mut input).unwrap(), Some((b'A', b"--width".to_vec())));
        assert_eq!(read(&mut input).unwrap(), Some((b'G', vec![])));
        assert_eq!(read(&mut input).unwrap(), None);
    }

    /// The largest single allocation made on each thread since its last reset (tests run on
    /// threads of their own, so others' allocations do not count).
    mod peak {
        use std::alloc::{GlobalAlloc, Layout, System};
        use std::cell::Cell;

        thread_local! {
            static LARGEST: Cell<usize> = const { Cell::new(0) };
        }

        pub struct Counting;

        // SAFETY: every call is passed to the system allocator unchanged; the thread-local
        // `Cell` is const-initialised (no allocation, no destructor).
        unsafe impl GlobalAlloc for Counting {
            unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
                note(layout.size());
                unsafe { System.alloc(layout) }
            }
            unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
                unsafe { System.dealloc(ptr, layout) }
            }
            unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
                note(new_size);
                unsafe { System.realloc(ptr, layout, new_size) }
            }
        }

        fn note(size: usize) {
            let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
        }

        pub fn reset() {
            LARGEST.with(|l| l.set(0));
        }

        pub fn largest() -> usize {
            LARGEST.with(|l| l.get())
        }
    }

    #[global_allocator]
    static ALLOCATOR: peak::Counting = peak::Counting;

    #[test]
    fn a_declared_length_is_not_allocated_before_the_bytes_come() {
        // 64 MiB declared, ten bytes sent, then the end
        let mut input: Vec<u8> = (MAX_FRAME as u32).to_be_bytes().to_vec();
        input.extend_from_slice(b"Ohello, wo");
        peak::reset();
        let e = read(&mut &input[..]).unwrap_err();
        let largest = peak::largest();
        assert!(largest < 64 * 1024, "allocated {largest} bytes for 10");
        assert_eq!(e.kind(), io::ErrorKind::UnexpectedEof);
        assert!(
            e.to_string()
                .contains("frame cut short: 10 of 67108864 bytes"),
            "{e}"
        );
        // a whole large frame still arrives whole
        let data = vec![7u8; 3 * 1024 * 1024];
        let mut buf = Vec::new();
        write(&mut buf, b'O', &data).unwrap();
        assert_eq!(read(&mut &buf[..]).unwrap(), Some((b'O', data)));
    }

    #[test]
    fn bad_lengths_are_errors() {
        let mut zero: &[u8] = &[0, 0, 0, 0];
        assert!(read(&mut zero).is_err());
        let mut huge: &[u8] = &[0xff, 0xff, 0xff, 0xff];
        assert!(read(&mut huge).is_err());
        let mut short: &[u8] = &[0, 0, 0, 9, b'O', b'x'];
        assert!(read(&mut short).is_err());
    }
}
