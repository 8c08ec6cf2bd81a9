//! Reading and writing numpy `.npz` archives. Writing: uncompressed like `numpy.savez`, so large arrays cost no
//! compression time, and strings as fixed-width unicode arrays, so `numpy.load` opens every
//! archive without `allow_pickle`.

use std::fs::File;
use std::io::{self, BufReader, BufWriter, Cursor, Read};
use std::path::Path;

use npyz::npz::NpzWriter;
use npyz::zip::{self, CompressionMethod};
use npyz::{DType, Deserialize, NpyFile, TypeStr, WriterBuilder};

use crate::error::InputError;

/// An `.npz` archive being written; [`NpzOut::finish`] completes it.
pub struct NpzOut {
    npz: NpzWriter<BufWriter<File>>,
}

/// How every array is stored: uncompressed, with Zip64 entries for arrays of 2 GiB and more,
/// and the zip format's earliest time (1980-01-01) as every entry's modification time, so an
/// archive's bytes depend only on its arrays (a dataset made twice is the same bytes).
pub(crate) fn entry_options() -> zip::write::FileOptions {
    zip::write::FileOptions::default()
        .compression_method(CompressionMethod::Stored)
        .large_file(true)
        .last_modified_time(zip::DateTime::default())
}

impl NpzOut {
    /// Creates (or truncates) the archive at `path`.
    pub fn create(path: &Path) -> io::Result<Self> {
        Ok(NpzOut {
            npz: NpzWriter::create(path)?,
        })
    }

    /// Writes a numeric array `name` of `shape` (row-major) with the default dtype of `T`
    /// (little-endian); `data` must hold the product of `shape` elements.
    pub fn array<T: npyz::AutoSerialize>(
        &mut self,
        name: &str,
        shape: &[u64],
        data: impl IntoIterator<Item = T>,
    ) -> io::Result<()> {
        let mut writer = self
            .npz
            .array::<T>(name, entry_options())?
            .default_dtype()
            .shape(shape)
            .begin_nd()?;
        writer.extend(data)?;
        writer.finish()
    }

    /// Writes strings as a fixed-width unicode (`<U`) array `name` of `shape`.
    pub fn strings<'a>(
        &mut self,
        name: &str,
        shape: &[u64],
        strings: impl IntoIterator<Item = &'a str> + Clone,
    ) -> io::Result<()> {
        let width = strings
            .clone()
            .into_iter()
            .map(|s| s.chars().count())
            .max()
            .unwrap_or(0)
            .max(1);
        let type_str: TypeStr = format!("<U{width}")
            .parse()
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, format!("{e}")))?;
        let mut writer = self
            .npz
            .array::<str>(name, entry_options())?
            .dtype(DType::Plain(type_str))
            .shape(shape)
            .begin_nd()?;
        for s in strings {
            writer.push(s)?;
        }
        writer.finish()
    }

    /// Writes the archive's directory and flushes the file.
    pub fn finish(mut self) -> io::Result<()> {
        let mut file = self.npz.zip_writer().finish()?;
        io::Write::flush(&mut file)
    }
}

// ---------------------------------------------------------------------------------------
// Reading

/// Largest expansion a deflate stream can give (about 1032:1), for a sanity bound on sizes.
const MAX_DEFLATE_RATIO: u64 = 1100;

/// An opened `.npz` archive that reports errors against its path.
pub struct NpzFile<'p> {
    path: &'p Path,
    zip: zip::ZipArchive<BufReader<File>>,
    file_len: u64,
}

impl<'p> NpzFile<'p> {
    /// Opens the archive at `path`.
    pub fn open(path: &'p Path) -> Result<Self, InputError> {
        let fail = |e: &dyn std::fmt::Display| InputError::file(path, format!("cannot open as an .npz archive: {e}"));
        let file = File::open(path).map_err(|e| fail(&e))?;
        let file_len = file.metadata().map_err(|e| fail(&e))?.len();
        let zip = zip::ZipArchive::new(BufReader::new(file)).map_err(|e| fail(&e))?;
        Ok(NpzFile { path, zip, file_len })
    }

    /// Whether the archive holds array `name`.
    pub fn has(&mut self, name: &str) -> bool {
        self.zip.by_name(&format!("{name}.npy")).is_ok()
    }

    /// Reads the whole entry of array `name` (checksum verified) and parses its header.
    pub fn array(&mut self, name: &'static str) -> Result<NpyArray<'p>, InputError> {
        let path = self.path;
        let err = |msg: String| InputError::field(path, name, msg);
        let mut entry = match self.zip.by_name(&format!("{name}.npy")) {
            Ok(entry) => entry,
            Err(zip::result::ZipError::FileNotFound) => return Err(err("missing".into())),
            Err(e) => return Err(err(format!("unreadable: {e}"))),
        };
        let size = entry.size();
        let packed = entry.compressed_size();
        let bound = match entry.compression() {
            CompressionMethod::Stored => packed,
            _ => packed.saturating_mul(MAX_DEFLATE_RATIO).saturating_add(1024),
        };
        if packed > self.file_len || size > bound {
            return Err(err(format!(
                "corrupt entry sizes ({size} bytes from {packed} packed, file is {} bytes)",
                self.file_len
            )));
        }
        let mut bytes = Vec::new();
        entry
            .by_ref()
            .take(size.saturating_add(1))
            .read_to_end(&mut bytes)
            .map_err(|e| err(format!("corrupt or truncated data: {e}")))?;
        if bytes.len() as u64 != size {
            return Err(err(format!(
                "entry holds {} bytes, its header says {size}",
                bytes.len()
            )));
        }
        NpyArray::parse(path, name, bytes)
    }
}

/// One array of the archive, its bytes in memory and its header checked against them.
pub struct NpyArray<'p> {
    path: &'p Path,
    name: &'static str,
    shape: Vec<u64>,
    npy: NpyFile<Cursor<Vec<u8>>>,
}

impl<'p> NpyArray<'p> {
    fn parse(path: &'p Path, name: &'static str, bytes: Vec<u8>) -> Result<Self, InputError> {
        let err = |msg: String| InputError::field(path, name, msg);
        let (header_end, shape, count) = pre_check_header(&bytes).map_err(err)?;
        let data_len = (bytes.len() - header_end) as u64;
        let npy = NpyFile::new(Cursor::new(bytes)).map_err(|e| err(format!("bad .npy header: {e}")))?;
        if npy.shape() != shape.as_slice() {
            return Err(err("bad .npy header: unreadable shape".into()));
        }
        let item = npy
            .dtype()
            .num_bytes()
            .ok_or_else(|| err("dtype has no fixed size (pickled objects?)".into()))?;
        let needed = count.checked_mul(item as u64);
        if needed != Some(data_len) {
            return Err(err(format!(
                "shape {shape:?} of {item}-byte items needs {} bytes, the file holds {data_len}",
                needed.map_or("too many".into(), |b| b.to_string())
            )));
        }
        Ok(NpyArray { path, name, shape, npy })
    }

    /// An error about this array, naming the file and the array.
    pub fn error(&self, msg: String) -> InputError {
        InputError::field(self.path, self.name, msg)
    }

    /// Refuses any other shape than `expected`.
    pub fn expect_shape(&self, expected: &[u64]) -> Result<(), InputError> {
        if self.shape == expected {
            Ok(())
        } else {
            Err(self.error(format!("shape {:?}, expected {expected:?}", self.shape)))
        }
    }

    /// The shape as `N` axis lengths.
    pub fn dims<const N: usize>(&self) -> Result<[usize; N], InputError> {
        let mut dims = [0usize; N];
        if self.shape.len() != N {
            return Err(self.error(format!(
                "shape {:?} has {} axes, expected {N}",
                self.shape,
                self.shape.len()
            )));
        }
        for (d, &s) in dims.iter_mut().zip(&self.shape) {
            *d = usize::try_from(s).map_err(|_| self.error(format!("axis length {s} too large")))?;
        }
        Ok(dims)
    }

    /// Refuses an axis `axis` of another length than `expected`.
    pub fn expect_len(&self, axis: &str, len: usize, expected: usize) -> Result<(), InputError> {
        if len == expected {
            Ok(())
        } else {
            Err(self.error(format!("{len} {axis}, positions has {expected}")))
        }
    }

    /// All elements in storage order, as `T` (`what` names the expected dtype in errors).
    pub fn into_vec<T: Deserialize>(self, what: &str) -> Result<Vec<T>, InputError> {
        let descr = self.npy.dtype().descr();
        let (path, name) = (self.path, self.name);
        let fortran = self.npy.order() == npyz::Order::Fortran && self.shape.len() > 1;
        if fortran {
            return Err(InputError::field(
                path,
                name,
                "Fortran-ordered arrays are not supported",
            ));
        }
        self.npy
            .into_vec::<T>()
            .map_err(|e| InputError::field(path, name, format!("expected {what} data, found dtype {descr}: {e}")))
    }
}

/// Checks the `.npy` pre-header and shape before `npyz` parses them, so that corrupt
/// lengths cannot make it allocate or overflow. Returns the end of the header, the shape
/// and the element count.
fn pre_check_header(bytes: &[u8]) -> Result<(usize, Vec<u64>, u64), String> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err("not a .npy array (no magic)".into());
    }
    let (len, start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let end = start
        .checked_add(len)
        .filter(|&end| end <= bytes.len())
        .ok_or("truncated .npy header")?;
    let text = std::str::from_utf8(&bytes[start..end]).map_err(|_| "header is not text")?;
    let after_key = text
        .find("'shape'")
        .map(|i| &text[i + "'shape'".len()..])
        .ok_or("header has no shape")?;
    let open = after_key.find('(').ok_or("unreadable shape")?;
    let close = after_key.find(')').ok_or("unreadable shape")?;
    if close < open {
        return Err("unreadable shape".into());
    }
    let mut shape = Vec::new();
    let mut count: u64 = 1;
    for axis in after_key[open + 1..close].split(',').map(str::trim) {
        if axis.is_empty() {
            continue;
        }
        let n: u64 = axis
            .trim_end_matches('L')
            .parse()
            .map_err(|_| format!("unreadable shape entry {axis:?}"))?;
        count = count.checked_mul(n).ok_or("shape is too large")?;
        shape.push(n);
    }
    Ok((end, shape, count))
}
