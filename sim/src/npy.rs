//! A streaming writer of NumPy `.npy` files (format 1.0, little-endian, C order).
//!
//! The training data runs to gigabytes, so rows are written as they are produced and
//! never held in memory; the row count is patched into the header when the file is
//! finished (the header reserves room for it). `numpy.load` (and so PyTorch) reads the
//! result directly, memory-mapped if wished.
//!
//! Written here rather than taken from a crate because no kept one streams an n-d
//! array whose length is known only at the end: `npyz` patches the count for 1-d
//! arrays only (`begin_1d`), `ndarray-npy` needs the whole shape up front, and a 1-d
//! array of sub-array rows (`('<f4', (d,))`) is read by `numpy.load` only when
//! memory-mapped (checked with numpy 2.4). The header is the format's 1.0 dict; CI
//! reads every exported array back in NumPy.

use anyhow::{Context, Result};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Element types written.
pub trait Element: Copy {
    const DESCR: &'static str;
    fn write(self, w: &mut impl Write) -> std::io::Result<()>;
}

impl Element for f32 {
    const DESCR: &'static str = "<f4";
    fn write(self, w: &mut impl Write) -> std::io::Result<()> {
        w.write_all(&self.to_le_bytes())
    }
}
impl Element for u8 {
    const DESCR: &'static str = "|u1";
    fn write(self, w: &mut impl Write) -> std::io::Result<()> {
        w.write_all(&[self])
    }
}
impl Element for u32 {
    const DESCR: &'static str = "<u4";
    fn write(self, w: &mut impl Write) -> std::io::Result<()> {
        w.write_all(&self.to_le_bytes())
    }
}

pub struct NpyWriter<T: Element> {
    path: PathBuf,
    file: BufWriter<File>,
    row_shape: Vec<usize>,
    row_len: usize,
    rows: u64,
    _t: std::marker::PhantomData<T>,
}

fn header(descr: &str, rows: u64, row_shape: &[usize]) -> Vec<u8> {
    let dims: String = row_shape.iter().map(|d| format!(", {d}")).collect();
    // the row count is right-aligned in 20 characters so that the header never changes length
    let dict = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({rows:>20}{dims}{}), }}",
        if row_shape.is_empty() { "," } else { "" }
    );
    let unpadded = 10 + dict.len() + 1;
    let total = unpadded.div_ceil(64) * 64;
    let mut h = Vec::with_capacity(total);
    h.extend_from_slice(b"\x93NUMPY\x01\x00");
    h.extend_from_slice(&((total - 10) as u16).to_le_bytes());
    h.extend_from_slice(dict.as_bytes());
    h.resize(total - 1, b' ');
    h.push(b'\n');
    h
}

impl<T: Element> NpyWriter<T> {
    /// A file of rows shaped `row_shape` (empty for scalars).
    pub fn create(path: &Path, row_shape: &[usize]) -> Result<Self> {
        let mut file = BufWriter::with_capacity(
            1 << 20,
            File::create(path).with_context(|| format!("cannot create {}", path.display()))?,
        );
        file.write_all(&header(T::DESCR, 0, row_shape))?;
        Ok(NpyWriter {
            path: path.to_owned(),
            file,
            row_shape: row_shape.to_vec(),
            row_len: row_shape.iter().product(),
            rows: 0,
            _t: std::marker::PhantomData,
        })
    }

    pub fn push(&mut self, row: &[T]) -> Result<()> {
        anyhow::ensure!(
            row.len() == self.row_len,
            "{}: row of {} values, expected {}",
            self.path.display(),
            row.len(),
            self.row_len
        );
        for &v in row {
            v.write(&mut self.file)?;
        }
        self.rows += 1;
        Ok(())
    }

    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Patches the row count into the header and closes the file.
    pub fn finish(mut self) -> Result<u64> {
        self.file.seek(SeekFrom::Start(0))?;
        self.file.write_all(&header(T::DESCR, self.rows, &self.row_shape))?;
        self.file.flush()?;
        Ok(self.rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_aligned_and_names_the_shape() {
        let h = header("<f4", 12, &[16, 1024]);
        assert_eq!(h.len() % 64, 0);
        let text = String::from_utf8_lossy(&h[10..]);
        assert!(text.contains("'shape': (                  12, 16, 1024)"), "{text}");
        assert_eq!(header("<f4", u64::MAX, &[16, 1024]).len(), h.len(), "row count never changes the length");
        assert!(String::from_utf8_lossy(&header("|u1", 3, &[])).contains("(                   3,)"));
    }

    #[test]
    fn writes_rows_and_patches_the_count() {
        let p = std::env::temp_dir().join(format!("spwi-npy-{}.npy", std::process::id()));
        let mut w = NpyWriter::<f32>::create(&p, &[2]).unwrap();
        w.push(&[1.0, 2.0]).unwrap();
        w.push(&[3.0, 4.0]).unwrap();
        assert!(w.push(&[1.0]).is_err());
        assert_eq!(w.finish().unwrap(), 2);
        let bytes = std::fs::read(&p).unwrap();
        let h = header("<f4", 2, &[2]);
        assert_eq!(&bytes[..h.len()], &h[..]);
        assert_eq!(&bytes[h.len()..h.len() + 4], &1.0f32.to_le_bytes());
        assert_eq!(bytes.len(), h.len() + 16);
        std::fs::remove_file(p).unwrap();
    }
}
