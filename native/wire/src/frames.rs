//! Plain zstd frames, bounded when decoded.

use std::io::Read;

use crate::Error;

/// zstd's level for `compress`: things compressed once and sent to every node (scenes).
const LEVEL: i32 = 3;

/// `bytes` as one zstd frame.
pub fn compress(bytes: &[u8]) -> Result<Vec<u8>, Error> {
    zstd::bulk::compress(bytes, LEVEL).map_err(|e| Error::InvalidArgument(format!("zstd: {e}")))
}

/// The bytes of the zstd frames `frames`, at most `max_bytes` of them: more, or a corrupt
/// frame, is an error. Read a piece at a time: nothing much larger than the output is made.
pub fn decompress(frames: &[u8], max_bytes: u64) -> Result<Vec<u8>, Error> {
    let corrupt = |e: std::io::Error| Error::Corrupt(format!("corrupt zstd data: {e}"));
    let decoder = zstd::stream::read::Decoder::with_buffer(frames).map_err(corrupt)?;
    let mut out = Vec::new();
    decoder
        .take(max_bytes.saturating_add(1))
        .read_to_end(&mut out)
        .map_err(corrupt)?;
    if out.len() as u64 > max_bytes {
        return Err(Error::Corrupt(format!(
            "zstd data holds more than {max_bytes} bytes"
        )));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_bounded() {
        let data = vec![7u8; 100_000];
        let z = compress(&data).unwrap();
        assert!(z.len() < 1000);
        assert_eq!(decompress(&z, 100_000).unwrap(), data);
        assert!(decompress(&z, 99_999).is_err());
        assert!(decompress(&z[..z.len() - 4], 100_000).is_err());
        assert!(decompress(b"not zstd", 100).is_err());
        assert_eq!(decompress(&compress(&[]).unwrap(), 0).unwrap(), b"");
    }
}
