//! The encoded training frames as rows that training reads in batches: held in memory, or
//! written once to a file in the run's workspace and read back a batch at a time when the
//! training split is larger than the memory budget (`mochi train --frame-memory`,
//! docs/design.md, decision 13). Every stage that reads training frames goes through
//! [`Rows`], so both holders give the same batches.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Rows of equal width that can be gathered by index: the training set of
/// [`crate::learn::train::train`] and of every pass over the training frames.
pub trait Rows: Sync {
    /// Number of rows.
    fn count(&self) -> usize;
    /// Values per row (0 when there are no rows).
    fn width(&self) -> usize;
    /// Appends rows `indices`, in that order, to `out` as `f32`.
    fn gather_f32(&self, indices: &[usize], out: &mut Vec<f32>) -> std::io::Result<()>;
    /// Appends rows `indices`, in that order, to `out` as `f64`.
    fn gather_f64(&self, indices: &[usize], out: &mut Vec<f64>) -> std::io::Result<()>;
    /// Row `i` as `f64`.
    fn row_f64(&self, i: usize) -> std::io::Result<Vec<f64>> {
        let mut out = Vec::with_capacity(self.width());
        self.gather_f64(&[i], &mut out)?;
        Ok(out)
    }
    /// The first row whose width differs from row 0's (rows of a file all have one width).
    fn ragged_row(&self) -> Option<usize> {
        None
    }
}

impl Rows for [Vec<f32>] {
    fn count(&self) -> usize {
        self.len()
    }
    fn width(&self) -> usize {
        self.first().map_or(0, Vec::len)
    }
    fn gather_f32(&self, indices: &[usize], out: &mut Vec<f32>) -> std::io::Result<()> {
        for &i in indices {
            out.extend_from_slice(row(self, i)?);
        }
        Ok(())
    }
    fn gather_f64(&self, indices: &[usize], out: &mut Vec<f64>) -> std::io::Result<()> {
        for &i in indices {
            out.extend(row(self, i)?.iter().map(|&v| v as f64));
        }
        Ok(())
    }
    fn ragged_row(&self) -> Option<usize> {
        self.iter().position(|r| r.len() != self.width())
    }
}

impl Rows for Vec<Vec<f32>> {
    fn count(&self) -> usize {
        self.len()
    }
    fn width(&self) -> usize {
        self.as_slice().width()
    }
    fn gather_f32(&self, indices: &[usize], out: &mut Vec<f32>) -> std::io::Result<()> {
        self.as_slice().gather_f32(indices, out)
    }
    fn gather_f64(&self, indices: &[usize], out: &mut Vec<f64>) -> std::io::Result<()> {
        self.as_slice().gather_f64(indices, out)
    }
    fn ragged_row(&self) -> Option<usize> {
        self.as_slice().ragged_row()
    }
}

fn row<T>(rows: &[Vec<T>], i: usize) -> std::io::Result<&[T]> {
    rows.get(i).map(Vec::as_slice).ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("row {i} asked for, there are {}", rows.len()),
        )
    })
}

/// The encoded training frames (`f64`, sequence after sequence), in memory or in a file.
#[derive(Debug)]
pub enum FrameRows {
    /// Every row in memory.
    Memory(Vec<Vec<f64>>),
    /// Rows in a file, read a batch at a time.
    Disk(RowFile),
}

impl FrameRows {
    /// Calls `each(first, rows)` on consecutive blocks of at most `chunk` rows (the index of
    /// the block's first row, the block's values row after row), in order: one pass over
    /// every frame that holds at most `chunk` rows at a time.
    pub fn for_each_block<E: From<std::io::Error>>(
        &self,
        chunk: usize,
        mut each: impl FnMut(usize, &[f64]) -> Result<(), E>,
    ) -> Result<(), E> {
        let chunk = chunk.max(1);
        let mut block = Vec::new();
        let mut first = 0;
        while first < self.count() {
            let indices: Vec<usize> = (first..(first + chunk).min(self.count())).collect();
            block.clear();
            self.gather_f64(&indices, &mut block)?;
            each(first, &block)?;
            first += indices.len();
        }
        Ok(())
    }

    /// Whether the rows are read from a file.
    pub fn on_disk(&self) -> bool {
        matches!(self, FrameRows::Disk(_))
    }
}

impl Rows for FrameRows {
    fn count(&self) -> usize {
        match self {
            FrameRows::Memory(rows) => rows.len(),
            FrameRows::Disk(file) => file.count,
        }
    }
    fn width(&self) -> usize {
        match self {
            FrameRows::Memory(rows) => rows.first().map_or(0, Vec::len),
            FrameRows::Disk(file) => file.width,
        }
    }
    fn gather_f32(&self, indices: &[usize], out: &mut Vec<f32>) -> std::io::Result<()> {
        match self {
            FrameRows::Memory(rows) => {
                for &i in indices {
                    out.extend(row(rows, i)?.iter().map(|&v| v as f32));
                }
                Ok(())
            }
            FrameRows::Disk(file) => file.read(indices, |v| out.push(v as f32)),
        }
    }
    fn gather_f64(&self, indices: &[usize], out: &mut Vec<f64>) -> std::io::Result<()> {
        match self {
            FrameRows::Memory(rows) => {
                for &i in indices {
                    out.extend_from_slice(row(rows, i)?);
                }
                Ok(())
            }
            FrameRows::Disk(file) => file.read(indices, |v| out.push(v)),
        }
    }
    fn ragged_row(&self) -> Option<usize> {
        match self {
            FrameRows::Memory(rows) => rows.iter().position(|r| r.len() != self.width()),
            FrameRows::Disk(_) => None,
        }
    }
}

/// A file of `f64` rows (little-endian, row after row, nothing else) made by [`RowWriter`]:
/// the run's own cache of its encoded frames, rewritten by every run, never read by another
/// program. No crate was a fit: memory-mapping (`memmap2`) would leave how much of the file
/// stays resident to the kernel, where the point is a bound the trainer sets.
#[derive(Debug)]
pub struct RowFile {
    path: PathBuf,
    file: Mutex<File>,
    count: usize,
    width: usize,
}

impl RowFile {
    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Reads rows `indices` in order, handing each value to `push`; errors name the file.
    fn read(&self, indices: &[usize], push: impl FnMut(f64)) -> std::io::Result<()> {
        self.read_rows(indices, push)
            .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", self.path.display())))
    }

    fn read_rows(&self, indices: &[usize], mut push: impl FnMut(f64)) -> std::io::Result<()> {
        let bytes_per_row = 8 * self.width;
        let mut buffer = vec![0u8; bytes_per_row];
        let mut file = self
            .file
            .lock()
            .map_err(|_| std::io::Error::other("a reader of the frame file panicked"))?;
        for &i in indices {
            if i >= self.count {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!("row {i} asked for, the file holds {}", self.count),
                ));
            }
            file.seek(SeekFrom::Start((i * bytes_per_row) as u64))?;
            file.read_exact(&mut buffer)?;
            for bytes in buffer.chunks_exact(8) {
                push(f64::from_le_bytes(bytes.try_into().expect("chunks of 8 bytes")));
            }
        }
        Ok(())
    }
}

/// Writes rows of one width to a new [`RowFile`].
pub struct RowWriter {
    path: PathBuf,
    out: BufWriter<File>,
    count: usize,
    width: usize,
}

impl RowWriter {
    /// Creates (or truncates) `path` for rows of `width` values.
    pub fn create(path: &Path, width: usize) -> std::io::Result<Self> {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        Ok(RowWriter {
            path: path.to_path_buf(),
            out: BufWriter::new(File::create(path)?),
            count: 0,
            width,
        })
    }

    /// Appends one row.
    pub fn push(&mut self, row: &[f64]) -> std::io::Result<()> {
        if row.len() != self.width {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("a row of {} values for a file of rows of {}", row.len(), self.width),
            ));
        }
        for v in row {
            self.out.write_all(&v.to_le_bytes())?;
        }
        self.count += 1;
        Ok(())
    }

    /// Flushes the rows and opens the file for reading.
    pub fn finish(self) -> std::io::Result<RowFile> {
        let file = self.out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        Ok(RowFile {
            file: Mutex::new(File::open(&self.path)?),
            path: self.path,
            count: self.count,
            width: self.width,
        })
    }
}

/// The largest resident set the process has had, in bytes (Linux's `VmHWM`); `None` where
/// the platform does not say.
pub fn peak_resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows() -> Vec<Vec<f64>> {
        (0..7)
            .map(|i| (0..5).map(|j| (i * 10 + j) as f64 + 0.125).collect())
            .collect()
    }

    fn on_disk(dir: &Path, rows: &[Vec<f64>]) -> FrameRows {
        let mut writer = RowWriter::create(&dir.join("frames.f64"), 5).unwrap();
        for r in rows {
            writer.push(r).unwrap();
        }
        FrameRows::Disk(writer.finish().unwrap())
    }

    #[test]
    fn a_file_gives_the_rows_memory_gives() {
        let dir = tempfile::tempdir().unwrap();
        let memory = FrameRows::Memory(rows());
        let disk = on_disk(dir.path(), &rows());
        assert_eq!((disk.count(), disk.width()), (7, 5));
        let indices = [6, 0, 3, 3, 1];
        let (mut a, mut b) = (Vec::new(), Vec::new());
        memory.gather_f64(&indices, &mut a).unwrap();
        disk.gather_f64(&indices, &mut b).unwrap();
        assert_eq!(a, b);
        assert_eq!(a[..5], rows()[6][..]);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        memory.gather_f32(&indices, &mut a).unwrap();
        disk.gather_f32(&indices, &mut b).unwrap();
        assert_eq!(a, b);
        let mut blocks = Vec::new();
        disk.for_each_block(3, |first, block| {
            blocks.push((first, block.len()));
            Ok::<(), std::io::Error>(())
        })
        .unwrap();
        assert_eq!(blocks, [(0, 15), (3, 15), (6, 5)]);
    }

    #[test]
    fn out_of_range_rows_and_wrong_widths_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let disk = on_disk(dir.path(), &rows());
        let err = disk.gather_f64(&[7], &mut Vec::new()).unwrap_err();
        assert!(err.to_string().contains("row 7"), "{err}");
        assert!(FrameRows::Memory(rows()).gather_f32(&[9], &mut Vec::new()).is_err());
        let mut writer = RowWriter::create(&dir.path().join("w.f64"), 5).unwrap();
        assert!(writer.push(&[1.0; 4]).is_err());
    }

    #[test]
    fn peak_memory_is_read_where_the_platform_says() {
        if cfg!(target_os = "linux") {
            assert!(peak_resident_bytes().unwrap() > 1 << 20);
        }
    }
}
