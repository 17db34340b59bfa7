//! docs/results.md, its plots and its pictures, from the measurements of `pixguide eval`.

use super::eval::{self, EvalArgs, MethodSpec, Outcome, PictureData, Record, NORM_SPP, PICTURE_METHODS};
use super::eval_plot::{self, Curve};
use anyhow::{Context, Result};
use denoiser::metrics::{self, ToneMap};
use std::fmt::Write as _;
use std::path::Path;

fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Which value of a record a table or plot shows.
#[derive(Clone, Copy)]
enum Metric {
    RelMse,
    Ssim,
}

impl Metric {
    fn of(self, r: &Record) -> f64 {
        match self {
            Metric::RelMse => r.rel_mse,
            Metric::Ssim => r.one_minus_ssim,
        }
    }
    fn name(self) -> &'static str {
        match self {
            Metric::RelMse => "relMSE",
            Metric::Ssim => "1−SSIM",
        }
    }
}

struct View<'a> {
    a: &'a EvalArgs,
    o: &'a Outcome,
}

impl View<'_> {
    fn rec(&self, scene: &eval::TestScene, spp: u32, m: &MethodSpec) -> Option<&Record> {
        self.o.quality(&scene.name, spp, m, self.a.seed, scene)
    }
    fn noisy(&self) -> &MethodSpec {
        &self.o.methods[0]
    }
    /// The scene's error normalised by its 2-spp noisy error.
    fn norm(&self, scene: &eval::TestScene, spp: u32, m: &MethodSpec, metric: Metric) -> Option<f64> {
        let base = metric.of(self.rec(scene, NORM_SPP, self.noisy())?);
        let v = metric.of(self.rec(scene, spp, m)?);
        (base > 0.0).then(|| v / base)
    }
    /// Mean over scenes of the raw and of the normalised value (scenes lacking it are left out).
    fn means(&self, spp: u32, m: &MethodSpec, metric: Metric) -> (Option<f64>, Option<f64>) {
        let raw: Vec<f64> = self.o.scenes.iter().filter_map(|s| self.rec(s, spp, m).map(|r| metric.of(r))).collect();
        let norm: Vec<f64> = self.o.scenes.iter().filter_map(|s| self.norm(s, spp, m, metric)).collect();
        (mean(&raw), mean(&norm))
    }
    fn mean_time(&self, spp: u32, m: &MethodSpec) -> Option<f64> {
        mean(&self.o.scenes.iter().filter_map(|s| self.rec(s, spp, m).map(|r| r.time_s)).collect::<Vec<_>>())
    }
}

fn f(v: Option<f64>, digits: usize) -> String {
    v.map(|x| format!("{x:.digits$}")).unwrap_or_else(|| "–".into())
}

fn machine() -> (usize, String) {
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).map(|v| v.trim().to_string()))
        .unwrap_or_else(|| "unknown CPU".into());
    (cores, cpu)
}

fn command_line() -> String {
    let mut args: Vec<String> = std::env::args().collect();
    if let Some(first) = args.first_mut() {
        *first = "pixguide".into();
    }
    args.iter().map(|a| if a.contains(' ') || a.is_empty() { format!("'{a}'") } else { a.clone() }).collect::<Vec<_>>().join(" ")
}

pub fn write(a: &EvalArgs, o: &Outcome, dir: &Path) -> Result<()> {
    let v = View { a, o };
    let rel = dir.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let avail: Vec<&MethodSpec> = o.methods.iter().filter(|m| m.available()).collect();
    let mut spps = a.spp.clone();
    spps.sort_unstable();
    spps.dedup();
    let (cores, cpu) = machine();
    let mut s = String::new();
    let w = &mut s;
    writeln!(w, "# Results: error against samples and against time\n")?;
    writeln!(w, "*Written by `pixguide eval` from its own measurements; regenerate it with the command below rather than editing it.*\n")?;
    writeln!(w, "- **command**: `{}`", command_line())?;
    writeln!(w, "- **date**: {} · **commit**: {}", super::train::iso_date_utc(), { let c = super::train::git_commit(); if c.is_empty() { "unknown".into() } else { c } })?;
    let loads = mean(&o.load_samples);
    writeln!(
        w,
        "- **machine**: {cores} cores (`nproc`), {cpu}; 1-minute load average {:.2} at the start, {:.2} at the end{} of this run. \
         All times are **wall seconds on this {cores}-core machine**, shared with whatever else ran (the load average says how much).",
        o.load_start,
        o.load_end,
        loads.map(|l| format!(", {l:.2} on average after each measurement")).unwrap_or_default()
    )?;
    let dates: Vec<&str> = o.records.values().map(|r| r.date.as_str()).filter(|d| !d.is_empty()).collect();
    let (first, last) = (dates.iter().min().copied().unwrap_or("–"), dates.iter().max().copied().unwrap_or("–"));
    writeln!(
        w,
        "- **this run**: {} measurements made, {} taken from the cache `{}` (measurements made between {first} and {last}, by this command with the same weights, seed and sizes), {} renders, {:.0} s.\n",
        o.measured,
        o.cached,
        a.cache.clone().unwrap_or_else(|| dir.join("cache.jsonl")).display(),
        o.renders,
        o.wall_s
    )?;
    writeln!(w, "## Protocol\n")?;
    writeln!(
        w,
        "Each test scene of `{}` ({}) is rendered at its reference's size with seed {} at {} spp and scored against its 8000-spp reference \
         (`references/` beside the list). relMSE = mean over pixels and channels of (x−y)²/(y²+10⁻⁴) and 1−SSIM (7×7 uniform window, data range 1), both after \
         tone map (a) of method.md §7.3 (c/(1+lum(c)/1.5), then ^(1/2.2), clipped), over the whole image (no border crop: tiled inference mirror-pads the \
         image, so border pixels are denoised too) — the numbers `pixguide render --reference` prints. **norm.** = the value divided by the same scene's \
         {NORM_SPP}-spp noisy error, then averaged over scenes (the paper's Table 2 convention, method.md §7.3).\n",
        a.scenes.display(),
        o.scenes.iter().map(|s| format!("{} {}×{}", s.name, s.width, s.height)).collect::<Vec<_>>().join(", "),
        a.seed,
        spps.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")
    )?;
    writeln!(
        w,
        "Each (scene, spp) is rendered twice with the same seed: without per-sample path descriptors (the input of noisy and KPCN-G) and with them \
         (every model with a path-manifold module); the command checks that both give the same radiance. **Time of a method** = wall seconds of \
         its render + preprocessing + tiled inference, measured; noisy = its render alone.\n"
    )?;
    writeln!(w, "| method | weights | status |\n|---|---|---|")?;
    for m in &o.methods {
        let file = m.file.as_ref().map(|p| format!("`{}`", p.display())).unwrap_or_else(|| "–".into());
        let status = match (&m.missing, &m.loaded) {
            (Some(why), _) => format!("not available ({why})"),
            (None, Some(l)) => format!(
                "{} model, preset {}, {} training steps, validation relMSE {:.4}",
                l.method,
                if l.preset.is_empty() { "?" } else { &l.preset },
                l.provenance.steps,
                l.provenance.validation_rel_mse
            ),
            (None, None) => "plain Monte Carlo, no denoising".into(),
        };
        writeln!(w, "| {} | {file} | {status} |", m.label)?;
    }

    writeln!(w, "\n## Quality, mean over the {} scenes (the paper's Table 2 layout)\n", o.scenes.len())?;
    writeln!(w, "Normalised by each scene's {NORM_SPP}-spp noisy error, then averaged (lower is better):\n")?;
    let header = |w: &mut String| -> std::fmt::Result {
        write!(w, "| method |")?;
        for spp in &spps {
            write!(w, " {spp} spp relMSE | {spp} spp 1−SSIM |")?;
        }
        writeln!(w)?;
        writeln!(w, "|---|{}", "---|".repeat(2 * spps.len()))
    };
    for normalised in [true, false] {
        if !normalised {
            writeln!(w, "\nThe same, raw (mean over scenes of the unnormalised errors):\n")?;
        }
        header(w)?;
        for m in &o.methods {
            if let Some(why) = &m.missing {
                writeln!(w, "| {} | not available ({why}) |", m.label)?;
                continue;
            }
            write!(w, "| {} |", m.label)?;
            for &spp in &spps {
                for metric in [Metric::RelMse, Metric::Ssim] {
                    let (raw, norm) = v.means(spp, m, metric);
                    write!(w, " {} |", if normalised { f(norm, 3) } else { f(raw, 4) })?;
                }
            }
            writeln!(w)?;
        }
    }

    // Plots.
    let curves = |metric: Metric, by_time: bool| -> Vec<Curve> {
        avail
            .iter()
            .enumerate()
            .map(|(k, m)| Curve {
                label: m.label.clone(),
                colour: k,
                points: spps
                    .iter()
                    .filter_map(|&spp| {
                        let y = v.means(spp, m, metric).1?;
                        let x = if by_time { v.mean_time(spp, m)? } else { spp as f64 };
                        Some((x, y))
                    })
                    .collect(),
            })
            .collect()
    };
    let spp_png = dir.join("error-vs-spp.png");
    let time_png = dir.join("error-vs-time.png");
    eval_plot::write_pair(&spp_png, "samples per pixel", Some(spps.iter().map(|&s| s as f64).collect()), ("relMSE / 2-spp noisy", &curves(Metric::RelMse, false)), ("1-SSIM / 2-spp noisy", &curves(Metric::Ssim, false)))?;
    eval_plot::write_pair(&time_png, "seconds (render + denoise)", None, ("relMSE / 2-spp noisy", &curves(Metric::RelMse, true)), ("1-SSIM / 2-spp noisy", &curves(Metric::Ssim, true)))?;
    writeln!(w, "\n## Error against samples per pixel and against time\n")?;
    writeln!(w, "Mean normalised error, log-log; one curve per method, plain Monte Carlo included (the paper's Fig. 4 and Fig. 10).\n")?;
    writeln!(w, "![error vs spp]({rel}/error-vs-spp.png)\n\n![error vs time]({rel}/error-vs-time.png)\n")?;
    writeln!(w, "Mean time per image (seconds: render + preprocessing + inference):\n")?;
    write!(w, "| method |")?;
    for spp in &spps {
        write!(w, " {spp} spp |")?;
    }
    writeln!(w, "\n|---|{}", "---|".repeat(spps.len()))?;
    for m in &avail {
        write!(w, "| {} |", m.label)?;
        for &spp in &spps {
            write!(w, " {} |", f(v.mean_time(spp, m), 2))?;
        }
        writeln!(w)?;
    }

    // Breakdown.
    writeln!(w, "\n## Runtime breakdown (the paper's Table 1)\n")?;
    let guided = o.methods.iter().find(|m| m.name == "guided");
    match guided {
        Some(g) if g.available() && a.breakdown_size > 0 => {
            let size = a.breakdown_size;
            writeln!(
                w,
                "The guided model on {} rendered at {size}×{size} with descriptors, wall seconds. D_P includes the path-manifold modules; \
                 E + blend includes recombining the two branches; tiling = cutting windows out of the prepared image and reading results back. \
                 Columns of the two branches (diffuse, specular) are summed.\n",
                o.breakdown_scene
            )?;
            writeln!(w, "| spp | render | preprocessing | D_G | D_P (with path module) | E + blend | tiling | total |\n|---|---|---|---|---|---|---|---|")?;
            for &spp in &spps {
                let k = o.records.values().find(|r| {
                    r.kind == "breakdown" && r.scene == o.breakdown_scene && r.spp == spp && r.weights == g.id && r.seed == a.seed && r.width == size && r.height == size
                });
                if let Some(r) = k {
                    writeln!(
                        w,
                        "| {spp} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
                        r.render_s,
                        r.prepare_s,
                        r.d_g_s,
                        r.d_p_s,
                        r.e_s,
                        r.gather_s + r.readback_s,
                        r.time_s
                    )?;
                }
            }
        }
        Some(g) if !g.available() => writeln!(w, "Needs the guided model: not available ({}).", g.missing.clone().unwrap_or_default())?,
        _ => writeln!(w, "Not measured (`--breakdown-size 0` or guided not among `--methods`).")?,
    }

    // Per scene.
    writeln!(w, "\n## Per scene\n")?;
    writeln!(w, "Each cell: raw error (normalised by the scene's {NORM_SPP}-spp noisy error). The mean row averages each over the scenes.\n")?;
    for metric in [Metric::RelMse, Metric::Ssim] {
        writeln!(w, "### {}\n", metric.name())?;
        for &spp in &spps {
            writeln!(w, "{spp} spp\n")?;
            write!(w, "| scene |")?;
            for m in &avail {
                write!(w, " {} |", m.label)?;
            }
            writeln!(w, "\n|---|{}", "---|".repeat(avail.len()))?;
            for sc in &o.scenes {
                write!(w, "| {} |", sc.name)?;
                for m in &avail {
                    let raw = v.rec(sc, spp, m).map(|r| metric.of(r));
                    write!(w, " {} ({}) |", f(raw, 4), f(v.norm(sc, spp, m, metric), 3))?;
                }
                writeln!(w)?;
            }
            write!(w, "| **mean** |")?;
            for m in &avail {
                let (raw, norm) = v.means(spp, m, metric);
                write!(w, " **{} ({})** |", f(raw, 4), f(norm, 3))?;
            }
            writeln!(w, "\n")?;
        }
    }

    // Pictures.
    let pics = eval::picture_scenes(a, &o.scenes);
    if !pics.is_empty() {
        writeln!(w, "## Pictures\n")?;
        writeln!(
            w,
            "Centre crops (at most 128×128) shown with tone map (a), the one the metrics use; the number under each name is the image's relMSE. \
             Error maps: per-pixel relMSE (mean over channels), log colour scale from 10⁻⁴ (dark) to 1 (yellow). W_G: the share of the \
             G-buffer denoiser per pixel in the guided model (viridis, 0 dark … 1 yellow), diffuse and specular branch (the paper's Fig. 5–7).\n"
        )?;
        for p in &pics {
            let mut ps = a.picture_spp.clone();
            ps.sort_unstable();
            ps.dedup();
            for spp in ps {
                let [i, e, wg] = eval::picture_paths(dir, p, spp).map(|x| x.file_name().unwrap().to_string_lossy().into_owned());
                writeln!(w, "### {p}, {spp} spp\n\n![{p} {spp} spp]({rel}/{i})\n\n![errors]({rel}/{e})\n\n![W_G]({rel}/{wg})\n")?;
            }
        }
    }
    super::denoise::ensure_parent(&a.out)?;
    std::fs::write(&a.out, s).with_context(|| format!("writing {}", a.out.display()))?;
    Ok(())
}

const CROP: usize = 128;
const LABEL_H: u32 = 28;
const GAP: u32 = 4;

/// A sheet of equally sized tiles in one row, each under a two-line label.
struct Sheet {
    px: Vec<u8>,
    w: u32,
    tile: (u32, u32),
}

impl Sheet {
    fn new(n: usize, tile: (u32, u32)) -> Sheet {
        let w = n as u32 * (tile.0 + GAP) - GAP;
        let h = tile.1 + LABEL_H;
        Sheet { px: vec![24u8; (w * h * 3) as usize], w, tile }
    }
    fn put(&mut self, k: usize, rgb8: &[u8], label: &str, sub: &str) {
        let x0 = k as u32 * (self.tile.0 + GAP);
        for y in 0..self.tile.1 {
            for x in 0..self.tile.0 {
                let o = (((LABEL_H + y) * self.w + x0 + x) * 3) as usize;
                let i = ((y * self.tile.0 + x) * 3) as usize;
                self.px[o..o + 3].copy_from_slice(&rgb8[i..i + 3]);
            }
        }
        eval_plot::text(&mut self.px, self.w, x0 + 2, 2, 2, [255, 255, 255], label);
        eval_plot::text(&mut self.px, self.w, x0 + 2, 15, 2, [200, 200, 200], sub);
    }
    fn save(self, path: &Path) -> Result<()> {
        let h = self.px.len() as u32 / 3 / self.w;
        renderer::film::png::write_rgb8(path, self.w, h, self.px).with_context(|| format!("writing {}", path.display()))?;
        Ok(())
    }
}

/// Crop window: centred, at most CROP per side.
fn crop_rect(w: usize, h: usize) -> (usize, usize, usize, usize) {
    let (cw, ch) = (w.min(CROP), h.min(CROP));
    ((w - cw) / 2, (h - ch) / 2, cw, ch)
}

/// Crop of a per-pixel map mapped to RGB8 by `colour`.
fn crop_map(v: &[f64], w: usize, h: usize, colour: impl Fn(f64) -> [u8; 3]) -> Vec<u8> {
    let (x0, y0, cw, ch) = crop_rect(w, h);
    let mut out = Vec::with_capacity(cw * ch * 3);
    for y in y0..y0 + ch {
        for x in x0..x0 + cw {
            out.extend(colour(v[y * w + x]));
        }
    }
    out
}

fn tonemapped(rgb: &[f32]) -> Vec<[f64; 3]> {
    metrics::tonemap(rgb, ToneMap::Paper).chunks(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn inferno_log(e: f64) -> [u8; 3] {
    let t = ((e.max(1e-12).log10() + 4.0) / 4.0).clamp(0.0, 1.0);
    let c = colorous::INFERNO.eval_continuous(t);
    [c.r, c.g, c.b]
}

fn viridis(x: f64) -> [u8; 3] {
    let c = colorous::VIRIDIS.eval_continuous(x.clamp(0.0, 1.0));
    [c.r, c.g, c.b]
}

/// A colour bar tile from 0 (bottom) to 1 (top) with end labels.
fn colour_bar(tile: (u32, u32), colour: impl Fn(f64) -> [u8; 3]) -> Vec<u8> {
    let mut out = vec![24u8; (tile.0 * tile.1 * 3) as usize];
    for y in 0..tile.1 {
        let c = colour(1.0 - y as f64 / (tile.1.max(2) - 1) as f64);
        for x in 0..tile.0.min(24) {
            let o = ((y * tile.0 + x) * 3) as usize;
            out[o..o + 3].copy_from_slice(&c);
        }
    }
    out
}

/// Images, error maps and W_G maps of one (scene, spp).
pub fn write_pictures(dir: &Path, p: &PictureData) -> Result<()> {
    let [images_png, errors_png, weights_png] = eval::picture_paths(dir, &p.scene, p.spp);
    let (w, h) = (p.width, p.height);
    let (_, _, cw, ch) = crop_rect(w, h);
    let tile = (cw as u32, ch as u32);
    let mut ordered: Vec<&(String, String, Vec<f32>, f64)> = Vec::new();
    for name in PICTURE_METHODS {
        ordered.extend(p.images.iter().filter(|i| i.0 == name));
    }
    let reference = tonemapped(&p.reference);
    let to8 = |t: &[[f64; 3]]| -> Vec<u8> {
        let (x0, y0, cw, ch) = crop_rect(w, h);
        let mut out = Vec::with_capacity(cw * ch * 3);
        for y in y0..y0 + ch {
            for x in x0..x0 + cw {
                out.extend(t[y * w + x].map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8));
            }
        }
        out
    };

    let mut sheet = Sheet::new(ordered.len() + 1, tile);
    for (k, (_, label, img, rel)) in ordered.iter().enumerate() {
        sheet.put(k, &to8(&tonemapped(img)), label, &format!("{rel:.4}"));
    }
    sheet.put(ordered.len(), &to8(&reference), "reference", "8000 spp");
    sheet.save(&images_png)?;

    let mut sheet = Sheet::new(ordered.len() + 1, tile);
    for (k, (_, label, img, rel)) in ordered.iter().enumerate() {
        let t = tonemapped(img);
        let err: Vec<f64> = t
            .iter()
            .zip(&reference)
            .map(|(x, y)| (0..3).map(|c| (x[c] - y[c]).powi(2) / (y[c] * y[c] + metrics::REL_MSE_EPS)).sum::<f64>() / 3.0)
            .collect();
        sheet.put(k, &crop_map(&err, w, h, inferno_log), label, &format!("relMSE {rel:.4}"));
    }
    sheet.put(ordered.len(), &colour_bar(tile, |t| inferno_log(10f64.powf(4.0 * t - 4.0))), "scale", "1E-4 to 1");
    sheet.save(&errors_png)?;

    let mut sheet = Sheet::new(3, tile);
    match &p.weights_g {
        Some(m) => {
            let d: Vec<f64> = m.diffuse.iter().map(|&x| x as f64).collect();
            let s: Vec<f64> = m.specular.iter().map(|&x| x as f64).collect();
            sheet.put(0, &crop_map(&d, w, h, viridis), "W_G diffuse", "guided");
            sheet.put(1, &crop_map(&s, w, h, viridis), "W_G specular", "guided");
        }
        None => {
            let blank = vec![24u8; (tile.0 * tile.1 * 3) as usize];
            sheet.put(0, &blank, "no guided", "model");
            sheet.put(1, &blank, "", "");
        }
    }
    sheet.put(2, &colour_bar(tile, viridis), "scale", "0 to 1");
    sheet.save(&weights_png)?;
    Ok(())
}
