//! The envelope shared by mochi's binary files (training checkpoints, model artifacts):
//!
//! ```text
//! magic: 8 bytes | format version: u32 LE | payload length: u64 LE | CRC-32 of payload: u32 LE | payload
//! ```
//!
//! so a file from another program, a newer format, a truncated copy or a flipped bit is refused
//! before its payload is parsed.

/// Bytes before the payload.
pub const HEADER_LEN: usize = 8 + 4 + 8 + 4;

/// `payload` in an envelope with `magic` and `version`.
pub fn wrap(magic: &[u8; 8], version: u32, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(magic);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    out.extend_from_slice(payload);
    out
}

/// The payload of an envelope, after checking magic, version, length and CRC; `what` names
/// the kind of file in error messages ("checkpoint", "model artifact").
pub fn unwrap<'a>(bytes: &'a [u8], magic: &[u8; 8], version: u32, what: &str) -> Result<&'a [u8], String> {
    if bytes.len() < magic.len() || &bytes[..magic.len()] != magic {
        return Err(format!("not a mochi {what} (bad magic bytes)"));
    }
    if bytes.len() < HEADER_LEN {
        return Err(format!("{what} is truncated: {} bytes", bytes.len()));
    }
    let word = |range: std::ops::Range<usize>| -> u64 {
        bytes[range].iter().rev().fold(0u64, |acc, &b| (acc << 8) | b as u64)
    };
    let found = word(8..12);
    if found != version as u64 {
        return Err(format!("{what} format version {found}, this build reads {version}"));
    }
    let payload_len = word(12..20);
    let payload = &bytes[HEADER_LEN..];
    if payload.len() as u64 != payload_len {
        return Err(format!(
            "{what} is truncated or padded: header says {payload_len} payload bytes, file has {}",
            payload.len()
        ));
    }
    if crc32fast::hash(payload) as u64 != word(20..24) {
        return Err(format!("{what} is corrupted (CRC-32 mismatch)"));
    }
    Ok(payload)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAGIC: &[u8; 8] = b"TESTTEST";

    #[test]
    fn round_trip_and_every_damage_is_refused() {
        let payload = b"some payload bytes".to_vec();
        let bytes = wrap(MAGIC, 3, &payload);
        assert_eq!(unwrap(&bytes, MAGIC, 3, "file").unwrap(), &payload[..]);
        assert!(unwrap(&bytes, b"OTHERMAG", 3, "file").unwrap_err().contains("magic"));
        assert!(unwrap(&bytes, MAGIC, 4, "file").unwrap_err().contains("version 3"));
        for cut in [0, 5, HEADER_LEN - 1, HEADER_LEN, bytes.len() - 1] {
            assert!(unwrap(&bytes[..cut], MAGIC, 3, "file").is_err(), "cut at {cut}");
        }
        let mut flipped = bytes.clone();
        *flipped.last_mut().unwrap() ^= 1;
        assert!(unwrap(&flipped, MAGIC, 3, "file").unwrap_err().contains("CRC"));
    }
}
