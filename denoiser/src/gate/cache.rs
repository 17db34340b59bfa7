//! The experts' outputs on every shot of a dataset, computed once: with the experts frozen, a step
//! of E then costs only E. One safetensors file per shot holds, per sample count, every expert's
//! output and the noisy buffers E reads, with the reference; its header names the experts' weights,
//! so a cache made with other weights is made again rather than reused.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use film::exr_io::read_frame;
use film::Descriptors;

use super::run::{run_experts, Experts};
use super::{Expert, GateFrame};
use crate::infer::InferOptions;
use crate::train::data::{read_index, spps_in};

/// One noisy image of a shot with what every expert made of it.
#[derive(Clone, Debug)]
pub struct CachedImage {
    pub spp: u32,
    pub width: usize,
    pub height: usize,
    /// Per cached expert, linear radiance `[H, W, 3]`.
    pub experts: Vec<(Expert, Vec<f32>)>,
    pub radiance: Vec<f32>,
    pub radiance_var: Vec<f32>,
    pub diffuse: Vec<f32>,
    pub specular: Vec<f32>,
    pub albedo: Vec<f32>,
    pub normal: Vec<f32>,
    pub depth: Vec<f32>,
    pub passthrough: Vec<bool>,
    pub reference: Vec<f32>,
}

impl CachedImage {
    pub fn gate_frame(&self) -> GateFrame<'_> {
        GateFrame {
            width: self.width,
            height: self.height,
            spp: self.spp,
            radiance: &self.radiance,
            radiance_var: &self.radiance_var,
            diffuse: &self.diffuse,
            specular: &self.specular,
            albedo: &self.albedo,
            normal: &self.normal,
            depth: &self.depth,
        }
    }

    /// The outputs of `which`, in that order (`None` if one is not cached).
    pub fn try_expert_images(&self, which: &[Expert]) -> Option<Vec<&[f32]>> {
        which.iter().map(|e| self.experts.iter().find(|(c, _)| c == e).map(|(_, v)| &v[..])).collect()
    }

    /// The outputs of `which`, in that order; every one must be cached ([`build`] checks).
    pub fn expert_images(&self, which: &[Expert]) -> Vec<&[f32]> {
        self.try_expert_images(which).expect("every expert asked for is cached")
    }
}

/// A shot's cached images.
#[derive(Clone, Debug)]
pub struct CachedShot {
    pub split: String,
    pub dir: String,
    pub images: Vec<CachedImage>,
}

/// The experts a cache can hold, in this order.
pub const CACHED: [Expert; 3] = [Expert::G, Expert::P, Expert::Oidn];

#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    #[error("{path}: {message}")]
    Data { path: PathBuf, message: String },
    #[error("{0}")]
    Gate(#[from] super::run::GateError),
}

fn data_err(path: &Path, message: impl std::fmt::Display) -> CacheError {
    CacheError::Data { path: path.to_path_buf(), message: message.to_string() }
}

/// The first `spp` samples of every pixel (each lower count of a shot is a prefix of its largest).
pub fn descriptor_prefix(d: &Descriptors, spp: u32) -> Descriptors {
    let fields = d.data.len() / (d.width as usize * d.height as usize * d.spp as usize).max(1);
    let (s_all, s) = (d.spp as usize, spp.min(d.spp) as usize);
    let mut out = Descriptors::new(d.width, d.height, s as u32);
    for (i, px) in out.data.chunks_exact_mut(s * fields).enumerate() {
        px.copy_from_slice(&d.data[i * s_all * fields..(i * s_all + s) * fields]);
    }
    out
}

const FIELDS: [&str; 9] = ["radiance", "radiance_var", "diffuse", "specular", "albedo", "normal", "depth", "passthrough", "reference"];

fn write_shot(path: &Path, shot: &CachedShot, ids: &str) -> Result<(), CacheError> {
    let mut tensors: Vec<(String, Vec<u8>, Vec<usize>)> = Vec::new();
    let bytes = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    for im in &shot.images {
        let (w, h) = (im.width, im.height);
        for (e, img) in &im.experts {
            tensors.push((format!("{}.expert.{}", im.spp, e.name()), bytes(img), vec![h, w, 3]));
        }
        let pt: Vec<f32> =
            if im.passthrough.is_empty() { vec![0.0; w * h] } else { im.passthrough.iter().map(|&b| b as u8 as f32).collect() };
        let planes: [(&str, &[f32], usize); 9] = [
            ("radiance", &im.radiance, 3),
            ("radiance_var", &im.radiance_var, 3),
            ("diffuse", &im.diffuse, 3),
            ("specular", &im.specular, 3),
            ("albedo", &im.albedo, 3),
            ("normal", &im.normal, 3),
            ("depth", &im.depth, 1),
            ("passthrough", &pt, 1),
            ("reference", &im.reference, 3),
        ];
        for (name, v, c) in planes {
            tensors.push((format!("{}.{name}", im.spp), bytes(v), vec![h, w, c]));
        }
    }
    let views: Vec<(String, safetensors::tensor::TensorView)> = tensors
        .iter()
        .map(|(n, b, s)| (n.clone(), safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b).expect("sizes match")))
        .collect();
    let meta =
        HashMap::from([("experts".to_string(), ids.to_string()), ("split".into(), shot.split.clone()), ("dir".into(), shot.dir.clone())]);
    let data = safetensors::serialize(views, Some(meta)).map_err(|e| data_err(path, e))?;
    film::exr_io::write_atomically(path, &data).map_err(|e| data_err(path, e))
}

fn read_shot(path: &Path, ids: &str) -> Option<CachedShot> {
    let bytes = std::fs::read(path).ok()?;
    let st = safetensors::SafeTensors::deserialize(&bytes).ok()?;
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).ok()?;
    let meta = meta.metadata().clone()?;
    if meta.get("experts")? != ids {
        return None;
    }
    let floats = |name: &str| -> Option<(Vec<f32>, Vec<usize>)> {
        let t = st.tensor(name).ok()?;
        Some((t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(), t.shape().to_vec()))
    };
    let mut spps: Vec<u32> = st.names().iter().filter_map(|n| n.strip_suffix(".reference")?.parse().ok()).collect();
    spps.sort_unstable();
    let mut images = Vec::new();
    for spp in spps {
        let get = |f: &str| floats(&format!("{spp}.{f}"));
        let (reference, shape) = get("reference")?;
        let experts: Vec<(Expert, Vec<f32>)> = CACHED.iter().filter_map(|&e| Some((e, get(&format!("expert.{}", e.name()))?.0))).collect();
        let mut v: HashMap<&str, Vec<f32>> = HashMap::new();
        for f in FIELDS {
            v.insert(f, get(f)?.0);
        }
        let mut take = |f: &str| v.remove(f).unwrap_or_default();
        images.push(CachedImage {
            spp,
            width: shape[1],
            height: shape[0],
            experts,
            radiance: take("radiance"),
            radiance_var: take("radiance_var"),
            diffuse: take("diffuse"),
            specular: take("specular"),
            albedo: take("albedo"),
            normal: take("normal"),
            depth: take("depth"),
            passthrough: take("passthrough").into_iter().map(|x| x > 0.5).collect(),
            reference,
        });
    }
    Some(CachedShot { split: meta.get("split")?.clone(), dir: meta.get("dir")?.clone(), images })
}

fn buffer(b: &Option<film::PixelBuffer>, name: &str, path: &Path) -> Result<Vec<f32>, CacheError> {
    b.as_ref().map(|p| p.mean.clone()).ok_or_else(|| data_err(path, format!("no {name} buffer")))
}

/// Computes (or reads back) the cache of every shot of dataset `root` into `cache_dir`, holding
/// the experts of [`CACHED`] that `experts` has loaded. `ids` identifies those experts' weights
/// (a cache file made with other ones is made again); `progress(done, total, dir)` after each shot.
pub fn build(
    root: &Path,
    cache_dir: &Path,
    experts: &Experts,
    ids: &str,
    opts: &InferOptions,
    device: &Device,
    progress: &mut dyn FnMut(usize, usize, &str),
) -> Result<Vec<CachedShot>, CacheError> {
    let index = read_index(root).map_err(|e| data_err(root, e))?;
    std::fs::create_dir_all(cache_dir).map_err(|e| data_err(cache_dir, e))?;
    let which: Vec<Expert> = CACHED
        .into_iter()
        .filter(|e| match e {
            Expert::G => experts.g.is_some(),
            Expert::P => experts.p.is_some(),
            Expert::Oidn => experts.oidn.is_some(),
        })
        .collect();
    let mut shots = Vec::new();
    for (k, (split, dir)) in index.iter().enumerate() {
        let file = cache_dir.join(format!("{}.safetensors", dir.replace(['/', '\\'], "__")));
        if let Some(shot) = read_shot(&file, ids) {
            shots.push(shot);
            progress(k + 1, index.len(), dir);
            continue;
        }
        let d = root.join(dir);
        let ref_path = d.join("reference.exr");
        let reference = read_frame(&ref_path).map_err(|e| data_err(&ref_path, e))?;
        let spps = spps_in(&d);
        let max = spps.iter().copied().max().ok_or_else(|| data_err(&d, "no noisy_<S>spp.exr"))?;
        let desc_path = d.join(format!("descriptors_{max}spp.safetensors"));
        let desc = Descriptors::read_safetensors(&desc_path).map_err(|e| data_err(&desc_path, e))?;
        let mut images = Vec::new();
        for spp in spps {
            let path = d.join(format!("noisy_{spp}spp.exr"));
            let mut frame = read_frame(&path).map_err(|e| data_err(&path, e))?;
            if (frame.width, frame.height) != (reference.width, reference.height) {
                return Err(data_err(&path, "size differs from the reference's"));
            }
            frame.descriptors = Some(descriptor_prefix(&desc, spp as u32));
            let out = run_experts(&mut frame, &which, experts, opts, device)?;
            images.push(CachedImage {
                spp: spp as u32,
                width: frame.width as usize,
                height: frame.height as usize,
                experts: which.iter().copied().zip(out.images).collect(),
                radiance: frame.radiance.mean.clone(),
                radiance_var: frame.radiance.var.clone(),
                diffuse: buffer(&frame.diffuse, "diffuse", &path)?,
                specular: buffer(&frame.specular, "specular", &path)?,
                albedo: buffer(&frame.albedo, "albedo", &path)?,
                normal: buffer(&frame.normal, "normal", &path)?,
                depth: buffer(&frame.depth, "depth", &path)?,
                passthrough: out.passthrough,
                reference: reference.radiance.mean.iter().map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 }).collect(),
            });
        }
        let shot = CachedShot { split: split.clone(), dir: dir.clone(), images };
        write_shot(&file, &shot, ids)?;
        shots.push(shot);
        progress(k + 1, index.len(), dir);
    }
    Ok(shots)
}
