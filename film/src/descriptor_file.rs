//! A descriptor file read in place: the records of one pixel at a time, from disk, instead of
//! the whole file in memory. A training set's descriptors (tens of GB at 64 spp) outgrow the
//! machine's memory long before its images do; training reads only the patches it cuts, and
//! the operating system's page cache keeps what fits.

use crate::descriptors::FIELDS;
use crate::{Error, Precision, Result};
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

/// The `descriptors` tensor of a safetensors file written by
/// [`crate::Descriptors::write_safetensors_as`]: its shape, precision and where its bytes start.
#[derive(Debug)]
pub struct DescriptorFile {
    path: PathBuf,
    file: File,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub precision: Precision,
    data_start: u64,
}

impl DescriptorFile {
    /// Opens the file and checks its header against its length; reads no records.
    pub fn open(path: &Path) -> Result<DescriptorFile> {
        let bad = |m: String| Error::image(path, m);
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        let mut n = [0u8; 8];
        file.read_exact(&mut n).map_err(|e| Error::io(path, e))?;
        let n = u64::from_le_bytes(n);
        // safetensors caps headers at 100 MB; ours are a few hundred bytes.
        if n > 100_000_000 || 8 + n > len {
            return Err(bad(format!("header length {n} does not fit the file's {len} bytes")));
        }
        let mut header = vec![0u8; n as usize];
        file.read_exact(&mut header).map_err(|e| Error::io(path, e))?;
        let header: serde_json::Value = serde_json::from_slice(&header).map_err(|e| bad(format!("header: {e}")))?;
        let t = header.get("descriptors").ok_or_else(|| bad("no tensor `descriptors`".into()))?;
        let precision = match t.get("dtype").and_then(|d| d.as_str()) {
            Some("F32") => Precision::F32,
            Some("BF16") => Precision::Bf16,
            d => return Err(bad(format!("tensor `descriptors` must be F32 or BF16, found {d:?}"))),
        };
        let nums = |key: &str| -> Option<Vec<u64>> { t.get(key)?.as_array()?.iter().map(|v| v.as_u64()).collect() };
        let shape = nums("shape").unwrap_or_default();
        let offsets = nums("data_offsets").unwrap_or_default();
        if shape.len() != 4 || shape[3] != FIELDS as u64 || shape[..3].iter().any(|&d| d == 0 || d > u32::MAX as u64) {
            return Err(bad(format!("tensor `descriptors` must be [H, W, S, {FIELDS}], found {shape:?}")));
        }
        let bytes = shape.iter().try_fold(precision.bytes() as u64, |a, &d| a.checked_mul(d));
        let (start, end) = match offsets[..] {
            [a, b] => (a, b),
            _ => return Err(bad(format!("tensor `descriptors` has data_offsets {offsets:?}"))),
        };
        if bytes != end.checked_sub(start) || (8 + n).checked_add(end) != Some(len) {
            return Err(bad(format!("tensor `descriptors` {shape:?} does not match its bytes {start}..{end} in a file of {len}")));
        }
        Ok(DescriptorFile {
            path: path.to_path_buf(),
            file,
            height: shape[0] as u32,
            width: shape[1] as u32,
            spp: shape[2] as u32,
            precision,
            data_start: 8 + n + start,
        })
    }

    /// Another handle on the same open file.
    pub fn try_clone(&self) -> Result<DescriptorFile> {
        Ok(DescriptorFile { path: self.path.clone(), file: self.file.try_clone().map_err(|e| Error::io(&self.path, e))?, ..*self })
    }

    /// The first `s` records of pixel `i` (row-major), as f32, into `out` (`s × FIELDS` values).
    pub fn read_prefix(&self, i: usize, s: usize, out: &mut [f32]) -> Result<()> {
        let (pixels, spp) = (self.width as usize * self.height as usize, self.spp as usize);
        if i >= pixels || s > spp || out.len() != s * FIELDS {
            return Err(Error::Invalid(format!(
                "{}: records 0..{s} of pixel {i} asked of a {}×{} file at {spp} spp (into {} values)",
                self.path.display(),
                self.width,
                self.height,
                out.len()
            )));
        }
        let b = self.precision.bytes();
        let mut buf = vec![0u8; s * FIELDS * b];
        let at = self.data_start + (i * spp * FIELDS * b) as u64;
        read_at(&self.file, &mut buf, at).map_err(|e| Error::io(&self.path, e))?;
        self.precision.decode(&buf, out);
        Ok(())
    }
}

/// Positioned read, which leaves the file shared between threads without a cursor to guard.
#[cfg(unix)]
fn read_at(f: &File, buf: &mut [u8], at: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(f, buf, at)
}

#[cfg(windows)]
fn read_at(f: &File, mut buf: &mut [u8], mut at: u64) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(f, buf, at)? {
            0 => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            k => {
                buf = &mut buf[k..];
                at += k as u64;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Descriptors;

    #[test]
    fn records_read_in_place_equal_the_whole_file() {
        for precision in [Precision::F32, Precision::Bf16] {
            let path = std::env::temp_dir().join(format!("pixguide_descfile_{precision:?}_{}.safetensors", std::process::id()));
            let mut d = Descriptors::new(4, 3, 5);
            d.data.iter_mut().enumerate().for_each(|(i, v)| *v = (i as f32 * 0.713).sin() * 1e3);
            d.write_safetensors_as(&path, precision).unwrap();
            let whole = Descriptors::read_safetensors(&path).unwrap();
            let f = DescriptorFile::open(&path).unwrap();
            assert_eq!((f.width, f.height, f.spp, f.precision), (4, 3, 5, precision));
            for i in 0..12 {
                for s in [0, 1, 3, 5] {
                    let mut out = vec![0.0; s * FIELDS];
                    f.read_prefix(i, s, &mut out).unwrap();
                    assert_eq!(out[..], whole.data[i * 5 * FIELDS..(i * 5 + s) * FIELDS], "pixel {i}, {s} samples");
                }
            }
            // Out of range: an error naming the file, not a panic.
            let mut out = vec![0.0; 6 * FIELDS];
            let e = f.read_prefix(0, 6, &mut out).unwrap_err().to_string();
            assert!(e.contains("pixguide_descfile") && e.contains("5 spp"), "{e}");
            assert!(f.read_prefix(12, 1, &mut out[..FIELDS]).is_err());
            // A truncated file is refused at open.
            let bytes = std::fs::read(&path).unwrap();
            std::fs::write(&path, &bytes[..bytes.len() - 2]).unwrap();
            let e = DescriptorFile::open(&path).unwrap_err().to_string();
            assert!(e.contains("does not match"), "{e}");
            std::fs::remove_file(&path).ok();
        }
    }
}
