//! The noisy input and Intel Open Image Denoise scored on a dataset's validation shots with the
//! score `pixguide train` gives a model there (`denoiser::train::validate_by_spp`): the test
//! relMSE over the same windows (the patch grid, minus the model's margin on every side), mean
//! over every (shot, sample count, window). Drawn beside the training curves, they say during a
//! run, without a full `pixguide eval`, how far a model is from the input and from the production
//! denoiser the issue measures it against.

use anyhow::{Context, Result};
use denoiser::metrics::{rel_mse, ToneMap};
use denoiser::oidn::Oidn;
use denoiser::train::data::{read_index, spps_in};
use denoiser::train::patches;
use renderer::film::exr_io::read_frame;
use std::path::Path;

/// One baseline's validation score.
#[derive(Clone, Debug, PartialEq)]
pub struct Baseline {
    pub label: &'static str,
    pub overall: f64,
    /// (samples per pixel, mean at that count), in increasing spp.
    pub by_spp: Vec<(usize, f64)>,
}

/// Copies the `p × p` window at (x, y) of an interleaved RGB image `w` pixels wide.
fn window(rgb: &[f32], w: usize, x: usize, y: usize, p: usize) -> Vec<f32> {
    (y..y + p).flat_map(|row| &rgb[3 * (row * w + x)..3 * (row * w + x + p)]).copied().collect()
}

/// Scores noisy and (when given) OIDN on the validation shots of dataset `root`. OIDN sees the
/// window the model sees, not the whole shot, so both work from the same context.
pub fn measure(root: &Path, patch: usize, margin: usize, oidn: Option<&Oidn>) -> Result<Vec<Baseline>> {
    let val: Vec<String> = read_index(root)?.into_iter().filter(|(split, _)| split == "val").map(|(_, dir)| dir).collect();
    anyhow::ensure!(!val.is_empty(), "{}: no validation shots in shots.jsonl", root.display());
    let spps = spps_in(&root.join(&val[0]));
    anyhow::ensure!(!spps.is_empty(), "{}: no noisy_<S>spp.exr files", root.join(&val[0]).display());
    let labels: Vec<&'static str> = if oidn.is_some() { vec!["noisy", "OIDN"] } else { vec!["noisy"] };
    // sums[method][spp] = (sum, count)
    let mut sums = vec![vec![(0.0f64, 0usize); spps.len()]; labels.len()];
    for dir in &val {
        let d = root.join(dir);
        let ref_path = d.join("reference.exr");
        let reference = read_frame(&ref_path).with_context(|| format!("reading {}", ref_path.display()))?;
        let (w, h) = (reference.width as usize, reference.height as usize);
        let target: Vec<f32> = reference.radiance.mean.iter().map(|v| v.max(0.0)).collect();
        let grid = patches::grid(w, h, patch);
        anyhow::ensure!(!grid.is_empty(), "{}: a {w}×{h} shot holds no {patch}² window", ref_path.display());
        for (k, &spp) in spps.iter().enumerate() {
            let path = d.join(format!("noisy_{spp}spp.exr"));
            let noisy = read_frame(&path).with_context(|| format!("reading {}", path.display()))?;
            anyhow::ensure!(
                (noisy.width as usize, noisy.height as usize) == (w, h),
                "{}: {}×{}, but its reference is {w}×{h}",
                path.display(),
                noisy.width,
                noisy.height
            );
            for &(x, y) in &grid {
                let t = window(&target, w, x, y, patch);
                let colour = window(&noisy.radiance.mean, w, x, y, patch);
                let score = |img: &[f32]| rel_mse(img, &t, patch, patch, ToneMap::Paper, margin);
                let mut scores = vec![score(&colour)];
                if let Some(o) = oidn {
                    let (albedo, normal) = match (&noisy.albedo, &noisy.normal) {
                        (Some(a), Some(n)) => (window(&a.mean, w, x, y, patch), window(&n.mean, w, x, y, patch)),
                        _ => anyhow::bail!("{}: no albedo/normal layers, which OIDN needs", path.display()),
                    };
                    let out = o.denoise(&colour, &albedo, &normal, patch, patch).with_context(|| format!("OIDN on {}", path.display()))?;
                    scores.push(score(&out));
                }
                for (m, s) in scores.into_iter().enumerate() {
                    sums[m][k].0 += s;
                    sums[m][k].1 += 1;
                }
            }
        }
    }
    Ok(labels
        .into_iter()
        .zip(sums)
        .map(|(label, per)| {
            let (s, n) = per.iter().fold((0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
            Baseline { label, overall: s / n as f64, by_spp: spps.iter().zip(&per).map(|(&spp, &(s, n))| (spp, s / n as f64)).collect() }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use renderer::film::exr_io::write_frame;
    use renderer::film::{Frame, PixelBuffer};

    fn frame(w: u32, h: u32, value: impl Fn(usize) -> f32) -> Frame {
        let n = (w * h) as usize;
        let mut radiance = PixelBuffer::new(3, n);
        for (i, v) in radiance.mean.iter_mut().enumerate() {
            *v = value(i / 3);
        }
        let mut albedo = PixelBuffer::new(3, n);
        albedo.mean.fill(0.5);
        let mut normal = PixelBuffer::new(3, n);
        normal.mean.chunks_mut(3).for_each(|c| c[2] = 1.0);
        Frame {
            width: w,
            height: h,
            spp: 4,
            radiance,
            diffuse: None,
            specular: None,
            albedo: Some(albedo),
            normal: Some(normal),
            depth: None,
            depth_scale: 1.0,
            descriptors: None,
            nonfinite_samples: 0,
        }
    }

    #[test]
    fn noisy_is_scored_on_the_grid_windows_inside_the_margin_only() {
        let root = std::env::temp_dir().join(format!("pixguide-val-baselines-{}", std::process::id()));
        let shot = root.join("val/a_1");
        std::fs::create_dir_all(&shot).unwrap();
        std::fs::write(root.join("shots.jsonl"), "{\"split\":\"val\",\"dir\":\"val/a_1\"}\n").unwrap();
        // 10×6 image, patch 4: the grid holds windows at x = 0 and 4 (y = 0). With margin 1 the
        // scored pixels are x ∈ {1, 2} and {5, 6}, y ∈ {1, 2}. The noisy image is 1 there and
        // 0 elsewhere except a huge value at x = 3 (in a window, but inside its margin) and
        // x = 9 (outside every window), which must not count.
        let (w, h) = (10u32, 6u32);
        write_frame(&frame(w, h, |_| 0.0), &shot.join("reference.exr")).unwrap();
        let noisy = |i: usize| match i % w as usize {
            3 | 9 => 1e6,
            1 | 2 | 5 | 6 if (1..=2).contains(&(i / w as usize)) => 1.0,
            _ => 0.0,
        };
        write_frame(&frame(w, h, noisy), &shot.join("noisy_4spp.exr")).unwrap();
        let b = measure(&root, 4, 1, None).unwrap();
        std::fs::remove_dir_all(&root).ok();
        // Every scored pixel has the same error: tone-mapped 1 against a reference of 0.
        let lum_1 = 1.0f64 / (1.0 + 1.0 / 1.5);
        let expected = lum_1.powf(1.0 / 2.2).powi(2) / 1e-4;
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].by_spp.len(), 1);
        assert!((b[0].overall / expected - 1.0).abs() < 1e-5, "{} vs {expected}", b[0].overall);
    }

    #[test]
    fn window_copies_rows_of_the_requested_block() {
        // 3×2 image, pixel value = 10·y + x in all channels.
        let img: Vec<f32> = (0..2).flat_map(|y| (0..3).flat_map(move |x| [(10 * y + x) as f32; 3])).collect();
        let wdw = window(&img, 3, 1, 0, 2);
        let firsts: Vec<f32> = wdw.chunks(3).map(|c| c[0]).collect();
        assert_eq!(firsts, vec![1.0, 2.0, 11.0, 12.0]);
    }
}
