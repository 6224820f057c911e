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
    let mut body = vec![0u8; len];
    input.read_exact(&mut body)?;
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
