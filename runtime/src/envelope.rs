//! The envelope of mochi's binary files (model artifacts, the trainer's checkpoints): one
//! owner for the bytes around a payload (docs/design.md, decision 4).
//!
//! ```text
//! magic: 8 bytes | format version: u32 LE | payload length: u64 LE | CRC-32 of payload: u32 LE | payload
//! ```
//!
//! A file from another program, a newer or older format, a truncated or padded copy and a
//! flipped bit are refused before the payload is parsed. Reading works on `&[u8]` without
//! allocating and never panics; `wrap` (feature `std`) writes, [`write_header`] writes the
//! header into a caller's buffer without allocating.
//!
//! A file may hold several envelopes back to back ("sections"): [`split`] opens the first and
//! returns the bytes after it, [`check_sections`] checks that those bytes are whole sections.

use core::fmt;

/// Bytes before the payload: magic, version (u32 LE), length (u64 LE), CRC-32 (u32 LE).
pub const HEADER_LEN: usize = 8 + 4 + 8 + 4;

/// Why an envelope was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EnvelopeError {
    /// The first 8 bytes are not the expected magic (or there are fewer than 8).
    BadMagic,
    /// Fewer bytes than a header.
    Truncated {
        /// Bytes there are.
        len: usize,
    },
    /// Written in a format version this build does not read.
    Version {
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        expected: u32,
    },
    /// The header's payload length disagrees with the bytes that follow it.
    Length {
        /// Payload length in the header.
        header: u64,
        /// Payload bytes present.
        found: u64,
    },
    /// The payload's CRC-32 does not match the header's.
    Corrupt,
}

impl fmt::Display for EnvelopeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            EnvelopeError::BadMagic => write!(f, "bad magic bytes"),
            EnvelopeError::Truncated { len } => {
                write!(f, "truncated: {len} bytes, shorter than the {HEADER_LEN}-byte header")
            }
            EnvelopeError::Version { found, expected } => {
                write!(f, "format version {found}, this build reads {expected}")
            }
            EnvelopeError::Length { header, found } => write!(
                f,
                "truncated or padded: the header says {header} payload bytes, {found} are present"
            ),
            EnvelopeError::Corrupt => write!(f, "corrupted (CRC-32 mismatch)"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for EnvelopeError {}

/// The parsed header of an envelope.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// First 8 bytes.
    pub magic: [u8; 8],
    /// Format version.
    pub version: u32,
    /// Payload length.
    pub len: u64,
    /// CRC-32 of the payload.
    pub crc: u32,
}

impl Header {
    /// The header at the start of `bytes`.
    pub fn parse(bytes: &[u8]) -> Result<Header, EnvelopeError> {
        let Some((&header, _)) = bytes.split_first_chunk::<HEADER_LEN>() else {
            return Err(EnvelopeError::Truncated { len: bytes.len() });
        };
        let mut magic = [0; 8];
        magic.copy_from_slice(&header[..8]);
        let word = |from: usize, to: usize| {
            header[from..to]
                .iter()
                .rev()
                .fold(0u64, |acc, &b| (acc << 8) | b as u64)
        };
        Ok(Header {
            magic,
            version: word(8, 12) as u32,
            len: word(12, 20),
            crc: word(20, 24) as u32,
        })
    }

    /// The header of an envelope around `payload`.
    pub fn of(magic: &[u8; 8], version: u32, payload: &[u8]) -> Header {
        Header {
            magic: *magic,
            version,
            len: payload.len() as u64,
            crc: crc32fast::hash(payload),
        }
    }

    /// The header as bytes.
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut out = [0; HEADER_LEN];
        out[..8].copy_from_slice(&self.magic);
        out[8..12].copy_from_slice(&self.version.to_le_bytes());
        out[12..20].copy_from_slice(&self.len.to_le_bytes());
        out[20..24].copy_from_slice(&self.crc.to_le_bytes());
        out
    }
}

/// The first envelope of `bytes` (magic `magic`, version `version`): its checked payload and
/// the bytes after it.
///
/// Checks, in order: the magic (refused first, so a foreign file is named as such even when
/// short), the header's presence, the version, that the payload fits, and its CRC-32.
pub fn split<'a>(bytes: &'a [u8], magic: &[u8; 8], version: u32) -> Result<(&'a [u8], &'a [u8]), EnvelopeError> {
    split_versions(bytes, magic, version..=version).map(|(_, payload, rest)| (payload, rest))
}

/// [`split`] for a reader of several versions: accepts any version in `versions` and returns
/// it with the payload (a version outside is refused naming the newest).
pub fn split_versions<'a>(
    bytes: &'a [u8],
    magic: &[u8; 8],
    versions: core::ops::RangeInclusive<u32>,
) -> Result<(u32, &'a [u8], &'a [u8]), EnvelopeError> {
    if bytes.get(..magic.len()) != Some(&magic[..]) {
        return Err(EnvelopeError::BadMagic);
    }
    let header = Header::parse(bytes)?;
    if !versions.contains(&header.version) {
        return Err(EnvelopeError::Version {
            found: header.version,
            expected: *versions.end(),
        });
    }
    let (payload, rest) = section(header, &bytes[HEADER_LEN..])?;
    Ok((header.version, payload, rest))
}

/// The payload of `bytes`, which must be exactly one envelope with `magic` and `version`.
pub fn open<'a>(bytes: &'a [u8], magic: &[u8; 8], version: u32) -> Result<&'a [u8], EnvelopeError> {
    let (payload, rest) = split(bytes, magic, version)?;
    if !rest.is_empty() {
        return Err(EnvelopeError::Length {
            header: payload.len() as u64,
            found: (payload.len() + rest.len()) as u64,
        });
    }
    Ok(payload)
}

/// Checks that `bytes` is a sequence of whole envelopes (any magic and version) whose payloads
/// match their CRC-32; returns how many there are.
pub fn check_sections(mut bytes: &[u8]) -> Result<usize, EnvelopeError> {
    let mut count = 0;
    while !bytes.is_empty() {
        let header = Header::parse(bytes)?;
        bytes = section(header, &bytes[HEADER_LEN..])?.1;
        count += 1;
    }
    Ok(count)
}

/// The payload `header` describes at the start of `body` (checked), and the bytes after it.
fn section(header: Header, body: &[u8]) -> Result<(&[u8], &[u8]), EnvelopeError> {
    let len = usize::try_from(header.len)
        .ok()
        .filter(|&n| n <= body.len())
        .ok_or(EnvelopeError::Length {
            header: header.len,
            found: body.len() as u64,
        })?;
    let (payload, rest) = body.split_at(len);
    if crc32fast::hash(payload) != header.crc {
        return Err(EnvelopeError::Corrupt);
    }
    Ok((payload, rest))
}

/// Writes the envelope header for `payload` into `out` (the payload goes after it).
pub fn write_header(out: &mut [u8; HEADER_LEN], magic: &[u8; 8], version: u32, payload: &[u8]) {
    *out = Header::of(magic, version, payload).to_bytes();
}

/// `payload` in an envelope with `magic` and `version`.
#[cfg(feature = "std")]
pub fn wrap(magic: &[u8; 8], version: u32, payload: &[u8]) -> std::vec::Vec<u8> {
    let mut out = std::vec::Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(&Header::of(magic, version, payload).to_bytes());
    out.extend_from_slice(payload);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAGIC: &[u8; 8] = b"TESTTEST";
    const PAYLOAD: &[u8] = b"some payload bytes";

    /// `PAYLOAD` in an envelope, without allocating.
    fn wrapped() -> [u8; HEADER_LEN + PAYLOAD.len()] {
        let mut out = [0; HEADER_LEN + PAYLOAD.len()];
        let (header, payload) = out.split_first_chunk_mut::<HEADER_LEN>().unwrap();
        write_header(header, MAGIC, 3, PAYLOAD);
        payload.copy_from_slice(PAYLOAD);
        out
    }

    #[test]
    fn round_trip() {
        let bytes = wrapped();
        assert_eq!(open(&bytes, MAGIC, 3), Ok(PAYLOAD));
        assert_eq!(split(&bytes, MAGIC, 3), Ok((PAYLOAD, &[][..])));
        assert_eq!(
            Header::parse(&bytes),
            Ok(Header {
                magic: *MAGIC,
                version: 3,
                len: PAYLOAD.len() as u64,
                crc: crc32fast::hash(PAYLOAD),
            })
        );
        // An empty payload is a valid envelope.
        let mut empty = [0; HEADER_LEN];
        write_header(&mut empty, MAGIC, 3, &[]);
        assert_eq!(open(&empty, MAGIC, 3), Ok(&[][..]));
    }

    #[cfg(feature = "std")]
    #[test]
    fn wrap_writes_the_same_bytes() {
        assert_eq!(wrap(MAGIC, 3, PAYLOAD), wrapped());
    }

    #[test]
    fn bad_magic_is_refused() {
        let bytes = wrapped();
        assert_eq!(open(&bytes, b"OTHERMAG", 3), Err(EnvelopeError::BadMagic));
        assert_eq!(open(&bytes[..5], MAGIC, 3), Err(EnvelopeError::BadMagic));
        assert_eq!(open(&[], MAGIC, 3), Err(EnvelopeError::BadMagic));
    }

    #[test]
    fn bad_version_is_refused_naming_both() {
        let bytes = wrapped();
        let err = open(&bytes, MAGIC, 4).unwrap_err();
        assert_eq!(err, EnvelopeError::Version { found: 3, expected: 4 });
        let mut text = heapless::String::<64>::new();
        fmt::write(&mut text, format_args!("{err}")).unwrap();
        assert_eq!(text, "format version 3, this build reads 4");
    }

    #[test]
    fn truncation_at_every_length_is_refused() {
        let bytes = wrapped();
        for cut in 0..bytes.len() {
            let err = open(&bytes[..cut], MAGIC, 3).unwrap_err();
            let expected = match cut {
                0..8 => EnvelopeError::BadMagic,
                8..HEADER_LEN => EnvelopeError::Truncated { len: cut },
                _ => EnvelopeError::Length {
                    header: PAYLOAD.len() as u64,
                    found: (cut - HEADER_LEN) as u64,
                },
            };
            assert_eq!(err, expected, "cut at {cut}");
        }
    }

    #[test]
    fn bad_length_is_refused() {
        let mut bytes = wrapped();
        // Longer than the bytes present, absurdly long, and padding after the payload.
        for len in [PAYLOAD.len() as u64 + 1, u64::MAX] {
            bytes[12..20].copy_from_slice(&len.to_le_bytes());
            assert_eq!(
                open(&bytes, MAGIC, 3),
                Err(EnvelopeError::Length {
                    header: len,
                    found: PAYLOAD.len() as u64
                })
            );
        }
        let mut padded = [0; HEADER_LEN + PAYLOAD.len() + 1];
        padded[..HEADER_LEN + PAYLOAD.len()].copy_from_slice(&wrapped());
        assert_eq!(
            open(&padded, MAGIC, 3),
            Err(EnvelopeError::Length {
                header: PAYLOAD.len() as u64,
                found: PAYLOAD.len() as u64 + 1
            })
        );
        // A shorter length leaves a payload whose CRC-32 does not match.
        bytes[12..20].copy_from_slice(&(PAYLOAD.len() as u64 - 1).to_le_bytes());
        assert_eq!(split(&bytes, MAGIC, 3).map(|_| ()), Err(EnvelopeError::Corrupt));
    }

    #[test]
    fn every_flipped_bit_is_refused() {
        let good = wrapped();
        for i in 0..good.len() * 8 {
            let mut bytes = good;
            bytes[i / 8] ^= 1 << (i % 8);
            assert!(open(&bytes, MAGIC, 3).is_err(), "bit {i} flipped was accepted");
        }
        let mut bytes = good;
        bytes[HEADER_LEN] ^= 1;
        assert_eq!(open(&bytes, MAGIC, 3), Err(EnvelopeError::Corrupt));
        let mut bytes = good;
        bytes[21] ^= 1;
        assert_eq!(open(&bytes, MAGIC, 3), Err(EnvelopeError::Corrupt));
    }

    #[test]
    fn sections_after_the_first_are_checked() {
        let one = wrapped();
        let mut two = [0; 2 * (HEADER_LEN + PAYLOAD.len())];
        two[..one.len()].copy_from_slice(&one);
        two[one.len()..].copy_from_slice(&one);
        let (payload, rest) = split(&two, MAGIC, 3).unwrap();
        assert_eq!(payload, PAYLOAD);
        assert_eq!(check_sections(rest), Ok(1));
        assert_eq!(check_sections(&[]), Ok(0));
        assert_eq!(check_sections(&rest[..5]), Err(EnvelopeError::Truncated { len: 5 }));
        assert!(check_sections(&rest[..rest.len() - 1]).is_err());
        let mut flipped = two;
        *flipped.last_mut().unwrap() ^= 1;
        assert_eq!(check_sections(&flipped[one.len()..]), Err(EnvelopeError::Corrupt));
        // `open` takes exactly one envelope.
        assert!(matches!(open(&two, MAGIC, 3), Err(EnvelopeError::Length { .. })));
    }
}
