//! Frames to and from one single-part EXR (f32, ZIP-compressed, channels named in `channels`).

use crate::channels::{self, Layer};
use crate::{Error, Result};
use crate::{Frame, PixelBuffer};
use exr::prelude::*;
use std::collections::HashMap;
use std::path::Path;

/// ZIP-compressed scan lines written in increasing order: with the default (unspecified) order
/// the parallel compressor emits blocks as they finish, so identical images could produce
/// different files.
fn deterministic_encoding() -> Encoding {
    Encoding { compression: Compression::ZIP16, blocks: Blocks::ScanLines, line_order: LineOrder::Increasing }
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so a
/// reader (or an interrupted run) never sees a half-written file.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = tmp_path(path);
    std::fs::write(&tmp, bytes).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

fn tmp_path(path: &Path) -> std::path::PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".partial");
    path.with_file_name(name)
}

fn push_layer(list: &mut Vec<AnyChannel<FlatSamples>>, layer: &Layer, buf: &PixelBuffer) {
    let n = buf.mean.len() / buf.channels;
    for c in 0..buf.channels {
        let mean: Vec<f32> = (0..n).map(|i| buf.mean[i * buf.channels + c]).collect();
        let var: Vec<f32> = (0..n).map(|i| buf.var[i * buf.channels + c]).collect();
        list.push(AnyChannel::new(layer.mean[c], FlatSamples::F32(mean)));
        list.push(AnyChannel::new(layer.var[c], FlatSamples::F32(var)));
    }
}

/// Writes every buffer of `frame` (descriptors go to their own file, see `Descriptors`).
pub fn write_frame(frame: &Frame, path: &Path) -> Result<()> {
    let mut list = Vec::new();
    push_layer(&mut list, &channels::RADIANCE, &frame.radiance);
    let aux = [
        (&channels::DIFFUSE, &frame.diffuse),
        (&channels::SPECULAR, &frame.specular),
        (&channels::ALBEDO, &frame.albedo),
        (&channels::NORMAL, &frame.normal),
        (&channels::DEPTH, &frame.depth),
    ];
    for (layer, buf) in aux {
        if let Some(b) = buf {
            push_layer(&mut list, layer, b);
        }
    }
    let mut attrs = LayerAttributes::default();
    // One attribute only: the exr crate keeps custom attributes in a HashMap, whose order (and
    // so the file's bytes) would change from run to run with two or more.
    let meta = format!("{}={} {}={:e}", channels::ATTR_SPP, frame.spp, channels::ATTR_DEPTH_SCALE, frame.depth_scale);
    attrs.other.insert(Text::from(channels::ATTR_META), AttributeValue::Text(Text::from(meta.as_str())));
    let size = (frame.width as usize, frame.height as usize);
    let layer = exr::image::Layer::new(size, attrs, deterministic_encoding(), AnyChannels::sort(list.into()));
    let image = Image::from_layer(layer);
    let tmp = tmp_path(path);
    image.write().to_file(&tmp).map_err(|e| Error::image(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

/// Reads a frame written by [`write_frame`] (or any EXR with at least `R,G,B`). Layers that are
/// absent come back as `None`; a missing variance channel reads as zeros.
pub fn read_frame(path: &Path) -> Result<Frame> {
    check_frame_size(path)?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| Error::image(path, e))?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.0, layer.size.1);
    let map: HashMap<String, Vec<f32>> =
        layer.channel_data.list.iter().map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect())).collect();
    let get = |l: &Layer| -> Option<PixelBuffer> {
        let mut buf = PixelBuffer::new(l.mean.len(), w * h);
        for (c, name) in l.mean.iter().enumerate() {
            let m = map.get(*name)?;
            for (i, &x) in m[..w * h].iter().enumerate() {
                buf.mean[i * buf.channels + c] = x;
            }
            if let Some(v) = map.get(l.var[c]) {
                for (i, &x) in v[..w * h].iter().enumerate() {
                    buf.var[i * buf.channels + c] = x;
                }
            }
        }
        Some(buf)
    };
    let radiance = get(&channels::RADIANCE).ok_or_else(|| Error::image(path, "no R, G, B channels"))?;
    let meta = match layer.attributes.other.get(&Text::from(channels::ATTR_META)) {
        Some(AttributeValue::Text(t)) => t.to_string(),
        _ => String::new(),
    };
    let field =
        |name: &str| meta.split_whitespace().find_map(|kv| kv.strip_prefix(name).and_then(|v| v.strip_prefix('=')).map(str::to_string));
    let spp = field(channels::ATTR_SPP).and_then(|v| v.parse().ok()).unwrap_or(0);
    let depth_scale = field(channels::ATTR_DEPTH_SCALE).and_then(|v| v.parse().ok()).unwrap_or(1.0);
    Ok(Frame {
        width: w as u32,
        height: h as u32,
        spp,
        radiance,
        diffuse: get(&channels::DIFFUSE),
        specular: get(&channels::SPECULAR),
        albedo: get(&channels::ALBEDO),
        normal: get(&channels::NORMAL),
        depth: get(&channels::DEPTH),
        depth_scale,
        descriptors: None,
        nonfinite_samples: 0,
    })
}

/// Refuses a file whose header claims a frame larger than a render can be, before the exr
/// crate allocates every channel at that size (its own limit is 2³⁰ per side, so a corrupt
/// header of a few bytes could ask for terabytes).
fn check_frame_size(path: &Path) -> Result<()> {
    use crate::{MAX_RESOLUTION_PIXELS, MAX_RESOLUTION_SIDE};
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| Error::image(path, e))?;
    for (i, h) in meta.headers.iter().enumerate() {
        let (w, hh) = (h.layer_size.0, h.layer_size.1);
        if w > MAX_RESOLUTION_SIDE as usize
            || hh > MAX_RESOLUTION_SIDE as usize
            || (w as u64).saturating_mul(hh as u64) > MAX_RESOLUTION_PIXELS
        {
            return Err(Error::image(
                path,
                format!("layer {i}: dataWindow of {w}×{hh} pixels is larger than any frame ({MAX_RESOLUTION_SIDE} per side, 2^26 pixels)"),
            ));
        }
    }
    Ok(())
}

/// Writes three planes of linear RGB (e.g. an environment map) as a plain `R,G,B` f32 EXR.
pub fn write_rgb_planes(path: &Path, width: u32, height: u32, [r, g, b]: [Vec<f32>; 3]) -> Result<()> {
    let (w, h) = (width as usize, height as usize);
    let list = vec![
        AnyChannel::new("R", FlatSamples::F32(r)),
        AnyChannel::new("G", FlatSamples::F32(g)),
        AnyChannel::new("B", FlatSamples::F32(b)),
    ];
    let layer = exr::image::Layer::new((w, h), LayerAttributes::default(), deterministic_encoding(), AnyChannels::sort(list.into()));
    let tmp = tmp_path(path);
    Image::from_layer(layer).write().to_file(&tmp).map_err(|e| Error::image(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Found by renderer/tests/fuzz_exr.rs: a 1×1 file whose dataWindow claims 100000×100000
    /// pixels made the exr crate allocate 40 GB per channel (an abort, not even a panic).
    #[test]
    fn huge_data_window_is_an_error_before_any_allocation() {
        let dir = std::env::temp_dir().join(format!("pixguide-exr-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("huge.exr");
        write_rgb_planes(&p, 1, 1, [vec![1.0], vec![1.0], vec![1.0]]).unwrap();
        assert!(read_frame(&p).is_ok());
        let mut bytes = std::fs::read(&p).unwrap();
        let key = b"dataWindow\0box2i\0";
        let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
        // xMax and yMax of the box (xMin, yMin, xMax, yMax as little-endian i32).
        bytes[at + 8..at + 12].copy_from_slice(&99_999i32.to_le_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&99_999i32.to_le_bytes());
        std::fs::write(&p, bytes).unwrap();
        let e = read_frame(&p).expect_err("an error").to_string();
        std::fs::remove_dir_all(&dir).ok();
        assert!(e.contains("huge.exr") && e.contains("dataWindow of 100000×100000"), "{e}");
    }
}
