//! The cache of finished measurements (one JSON [`Record`] per line of `cache.jsonl`), their
//! keys, and the file hash that ties a key to the exact weights and reference it was measured with.

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

/// One finished measurement (a line of the cache).
#[derive(Clone, Debug, Serialize, Deserialize, Default)]
#[serde(default)]
pub struct Record {
    /// "quality" or "breakdown".
    pub kind: String,
    pub scene: String,
    pub spp: u32,
    pub method: String,
    pub weights: String,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    /// [`TestScene::reference_id`](super::scenes::TestScene::reference_id) of a quality
    /// record's reference ("" for breakdowns, which measure time only).
    pub reference: String,
    pub rel_mse: f64,
    pub rel_mse_gamma: f64,
    pub one_minus_ssim: f64,
    /// Wall seconds of the render this method's input came from.
    pub render_s: f64,
    /// Preprocessing (method.md §2, §4.1).
    pub prepare_s: f64,
    /// Tiled inference, everything.
    pub denoise_s: f64,
    /// render + preprocessing + inference: the time of the method.
    pub time_s: f64,
    pub gather_s: f64,
    pub d_g_s: f64,
    pub d_p_s: f64,
    pub e_s: f64,
    pub readback_s: f64,
    /// UTC date of the measurement and the 1-minute load average right after it.
    pub date: String,
    pub load1: f64,
    /// Mean weight per expert over the image, keyed by the expert's name, for methods that blend
    /// experts (a guided model's W); for a bound, the share of pixels taken from each expert.
    /// None for the others, and in lines written before the field existed.
    pub mean_w: Option<Vec<(String, f64)>>,
}

impl Record {
    fn key(&self) -> String {
        key(&self.kind, &self.scene, &self.reference, self.spp, &self.method, &self.weights, self.seed, self.width, self.height)
    }
}

#[allow(clippy::too_many_arguments)]
pub(super) fn key(kind: &str, scene: &str, reference: &str, spp: u32, method: &str, weights: &str, seed: u64, w: u32, h: u32) -> String {
    format!("{kind}|{scene}@{reference}|{spp}|{method}|{weights}|{seed}|{w}x{h}")
}

fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h = (h ^ *b as u64).wrapping_mul(0x100_0000_01b3);
    }
    h
}

/// Size and FNV-1a 64 hash of a file: changes whenever the weights do.
pub(super) fn file_id(path: &Path) -> Result<String> {
    // The same identity a gate file records for its experts.
    Ok(denoiser::gate::file::file_id(path)?)
}

fn read_cache(path: &Path) -> Result<HashMap<String, Record>> {
    let mut map = HashMap::new();
    let Ok(text) = std::fs::read_to_string(path) else { return Ok(map) };
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        // A line cut short by an interrupted run is skipped: it is measured again.
        match serde_json::from_str::<Record>(line) {
            Ok(r) => {
                map.insert(r.key(), r);
            }
            Err(e) => eprintln!("warning: {} line {}: {e}; ignored", path.display(), n + 1),
        }
    }
    Ok(map)
}

pub(super) struct Cache {
    pub(super) map: HashMap<String, Record>,
    file: std::fs::File,
}

impl Cache {
    pub(super) fn open(path: &Path) -> Result<Cache> {
        crate::cli::denoise::ensure_parent(path)?;
        let map = read_cache(path)?;
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .with_context(|| format!("opening the cache {}", path.display()))?;
        Ok(Cache { map, file })
    }
    pub(super) fn get(&self, k: &str) -> Option<&Record> {
        self.map.get(k)
    }
    pub(super) fn put(&mut self, r: Record) -> Result<()> {
        writeln!(self.file, "{}", serde_json::to_string(&r)?)?;
        self.file.flush()?;
        self.map.insert(r.key(), r);
        Ok(())
    }
}

/// The denoised images the bounds choose among, one EXR each (f32, ZIP-compressed: lossless, so
/// a resumed run's bounds are those of a fresh one), named after the measurement's key. Kept
/// apart from the page's folder (by default under target/), as the page's folder is committed
/// and the images are tens of MB; without them a run measures the experts again.
pub(super) struct ImageStore {
    dir: std::path::PathBuf,
}

impl ImageStore {
    pub(super) fn new(dir: &Path) -> Result<ImageStore> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(ImageStore { dir: dir.to_path_buf() })
    }
    /// The file of an image whose measurement has key `key`: readable prefix, then a hash of the
    /// whole key (weights, reference, seed and size included).
    pub(super) fn path(&self, key: &str, scene: &str, spp: u32, seed: u64, name: &str) -> std::path::PathBuf {
        let safe: String = name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
        self.dir.join(format!("{scene}-{spp}spp-seed{seed}-{safe}-{:016x}.exr", fnv1a(key.as_bytes())))
    }
    pub(super) fn put(&self, path: &Path, w: usize, h: usize, rgb: &[f32]) -> Result<()> {
        let plane = |c: usize| -> Vec<f32> { rgb.iter().skip(c).step_by(3).copied().collect() };
        renderer::film::exr_io::write_rgb_planes(path, w as u32, h as u32, [plane(0), plane(1), plane(2)])
            .with_context(|| format!("writing {}", path.display()))
    }
    /// The image, or None when it is missing or unreadable (then its method is measured again).
    pub(super) fn get(&self, path: &Path, w: usize, h: usize) -> Option<Vec<f32>> {
        if !path.exists() {
            return None;
        }
        match renderer::film::exr_io::read_frame(path) {
            Ok(f) if f.width as usize == w && f.height as usize == h => Some(f.radiance.mean),
            Ok(f) => {
                eprintln!("warning: {} is {}×{}, expected {w}×{h}; measured again", path.display(), f.width, f.height);
                None
            }
            Err(e) => {
                eprintln!("warning: {}: {e}; measured again", path.display());
                None
            }
        }
    }
}
