//! docs/results.md, its plots and its pictures, from the measurements of `pixguide eval`.

use super::eval::{self, EvalArgs, MethodSpec, Outcome, PictureData, Record, BREAKDOWN_METHODS, NORM_SPP, PICTURE_METHODS};
use super::eval_plot::{self, Curve};
use super::font;
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
        "Each (scene, spp) is rendered twice with the same seed: without per-sample path descriptors (the input of noisy, D_G and OIDN) and with them \
         (every model with a path-manifold module); the command checks that both give the same radiance. **Time of a method** = wall seconds of \
         its render + preprocessing + tiled inference, measured; noisy = its render alone; OIDN = its render + OIDN's filter (commit + execute, \
         after one untimed warm-up run per eval run), without loading the library and creating OIDN's device, done once per run.\n"
    )?;
    writeln!(
        w,
        "**OIDN** is a baseline outside the paper: Intel Open Image Denoise, a production denoiser with its own pretrained weights (trained by \
         Intel on its own data, not on our dataset), on the same noisy radiance with our albedo and normal G-buffers. `pixguide eval` installs it \
         the first time (a Python venv at `target/oidn-venv`, `pip install {}`: the wheel ships the C library) and calls its C API in process; \
         Python is only the installer.\n",
        super::oidn_setup::PACKAGE
    )?;
    writeln!(w, "| method | weights | status |\n|---|---|---|")?;
    for m in &o.methods {
        let file = match (&m.file, m.name.as_str()) {
            (Some(p), _) => format!("`{}`", p.display()),
            (None, "oidn") => "its own, built into the library".into(),
            (None, _) => "–".into(),
        };
        let status = match (&m.missing, &m.loaded, &m.oidn) {
            (Some(why), ..) => format!("not available ({why})"),
            (None, Some(l), _) => format!(
                "{} model, preset {}, {} training steps, validation relMSE {:.4}",
                l.method,
                if l.preset.is_empty() { "?" } else { &l.preset },
                l.provenance.steps,
                l.provenance.validation_rel_mse
            ),
            (None, None, Some(o)) => super::oidn_setup::describe(o),
            (None, None, None) => "plain Monte Carlo, no denoising".into(),
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
    eval_plot::write_pair(&spp_png, "samples per pixel", Some(spps.iter().map(|&s| s as f64).collect()), ("relMSE / 2-spp noisy", &curves(Metric::RelMse, false)), ("1 − SSIM / 2-spp noisy", &curves(Metric::Ssim, false)))?;
    eval_plot::write_pair(&time_png, "seconds (render + denoise)", None, ("relMSE / 2-spp noisy", &curves(Metric::RelMse, true)), ("1 − SSIM / 2-spp noisy", &curves(Metric::Ssim, true)))?;
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
    let asked: Vec<&MethodSpec> = BREAKDOWN_METHODS.iter().filter_map(|n| o.methods.iter().find(|m| m.name == *n)).collect();
    if a.breakdown_size == 0 || asked.is_empty() {
        writeln!(w, "Not measured (`--breakdown-size 0`, or neither guided nor oidn among `--methods`).")?;
    }
    for m in asked.iter().filter(|m| a.breakdown_size > 0 && !m.available()) {
        writeln!(w, "{}: not available ({}).\n", m.label, m.missing.clone().unwrap_or_default())?;
    }
    let shown: Vec<&&MethodSpec> = asked.iter().filter(|m| a.breakdown_size > 0 && m.available()).collect();
    if !shown.is_empty() {
        let size = a.breakdown_size;
        writeln!(
            w,
            "Wall seconds on {1} rendered at {size}×{size}, for {0}. The guided model renders with descriptors; D_P includes the path-manifold modules; \
             E + blend includes recombining the two branches; tiling = cutting windows out of the prepared image and reading results back; columns \
             of the two branches (diffuse, specular) are summed. OIDN renders without descriptors; its filter = OIDN's RT filter, commit + execute.\n",
            shown.iter().map(|m| m.label.as_str()).collect::<Vec<_>>().join(" and "),
            o.breakdown_scene
        )?;
        writeln!(w, "| spp | method | render | preprocessing | D_G | D_P (with path module) | E + blend | tiling | OIDN filter | total |\n|---|---|---|---|---|---|---|---|---|---|")?;
        for &spp in &spps {
            for m in &shown {
                let found = o.records.values().find(|r| {
                    r.kind == "breakdown" && r.method == m.name && r.scene == o.breakdown_scene && r.spp == spp && r.weights == m.id && r.seed == a.seed && r.width == size && r.height == size
                });
                let Some(r) = found else { continue };
                if m.oidn.is_some() {
                    writeln!(w, "| {spp} | {} | {:.2} | – | – | – | – | – | {:.2} | {:.2} |", m.label, r.render_s, r.denoise_s, r.time_s)?;
                } else {
                    writeln!(
                        w,
                        "| {spp} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | – | {:.2} |",
                        m.label,
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
            "Whole frames shown with tone map (a), the one the metrics use; the number under each name is the image's relMSE. The second row \
             enlarges {ZOOM}× the window (1/{ZOOM} of each side, outlined above) where the denoised images' summed squared error of the displayed \
             colours is largest, with the window's mean relMSE. \
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

/// Side of the zoom window as a fraction of the image side; zooms are shown at this factor.
const ZOOM: usize = 3;
const LABEL_H: u32 = 28;
const GAP: u32 = 4;

/// A grid of equally sized tiles, each under a two-line label.
struct Sheet {
    px: Vec<u8>,
    w: u32,
    tile: (u32, u32),
}

impl Sheet {
    fn new(cols: usize, rows: usize, tile: (u32, u32)) -> Sheet {
        let w = cols as u32 * (tile.0 + GAP) - GAP;
        let h = rows as u32 * (tile.1 + LABEL_H + GAP) - GAP;
        Sheet { px: vec![24u8; (w * h * 3) as usize], w, tile }
    }
    /// Puts an RGB8 image of `size` (at most the tile) at the tile's top-left corner.
    fn put(&mut self, row: usize, col: usize, rgb8: &[u8], size: (u32, u32), label: &str, sub: &str) {
        let x0 = col as u32 * (self.tile.0 + GAP);
        let y0 = row as u32 * (self.tile.1 + LABEL_H + GAP);
        for y in 0..size.1.min(self.tile.1) {
            for x in 0..size.0.min(self.tile.0) {
                let o = (((y0 + LABEL_H + y) * self.w + x0 + x) * 3) as usize;
                let i = ((y * size.0 + x) * 3) as usize;
                self.px[o..o + 3].copy_from_slice(&rgb8[i..i + 3]);
            }
        }
        let max_w = self.tile.0.saturating_sub(3);
        font::label(&mut self.px, self.w, (x0 + 2, y0 + 1), max_w, 13.0, [255, 255, 255], label);
        font::label(&mut self.px, self.w, (x0 + 2, y0 + 15), max_w, 12.0, [200, 200, 200], sub);
    }
    fn save(self, path: &Path) -> Result<()> {
        let h = self.px.len() as u32 / 3 / self.w;
        renderer::film::png::write_rgb8(path, self.w, h, self.px).with_context(|| format!("writing {}", path.display()))?;
        Ok(())
    }
}

/// A window of the image: origin and size in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Window {
    x: usize,
    y: usize,
    w: usize,
    h: usize,
}

/// The `w/ZOOM × h/ZOOM` window with the largest sum of `score` (a per-pixel map of a `w × h`
/// image), through a summed-area table; ties go to the first in reading order.
fn hardest_window(score: &[f64], w: usize, h: usize) -> Window {
    let (cw, ch) = ((w / ZOOM).max(1), (h / ZOOM).max(1));
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        for x in 0..w {
            let v = if score[y * w + x].is_finite() { score[y * w + x] } else { 0.0 };
            sat[(y + 1) * (w + 1) + x + 1] = v + sat[y * (w + 1) + x + 1] + sat[(y + 1) * (w + 1) + x] - sat[y * (w + 1) + x];
        }
    }
    let sum = |x: usize, y: usize| sat[(y + ch) * (w + 1) + x + cw] - sat[y * (w + 1) + x + cw] - sat[(y + ch) * (w + 1) + x] + sat[y * (w + 1) + x];
    let mut best = (f64::NEG_INFINITY, Window { x: 0, y: 0, w: cw, h: ch });
    for y in 0..=h - ch {
        for x in 0..=w - cw {
            let v = sum(x, y);
            if v > best.0 {
                best = (v, Window { x, y, w: cw, h: ch });
            }
        }
    }
    best.1
}

/// RGB8 of a whole `w`-wide per-pixel colour list.
fn rgb8(c: &[[u8; 3]]) -> Vec<u8> {
    c.iter().flatten().copied().collect()
}

/// The window of a `w`-wide colour list, enlarged ZOOM× by pixel repetition.
fn zoomed(c: &[[u8; 3]], w: usize, win: Window) -> (Vec<u8>, (u32, u32)) {
    let (zw, zh) = (win.w * ZOOM, win.h * ZOOM);
    let mut out = Vec::with_capacity(zw * zh * 3);
    for y in 0..zh {
        for x in 0..zw {
            out.extend(c[(win.y + y / ZOOM) * w + win.x + x / ZOOM]);
        }
    }
    (out, (zw as u32, zh as u32))
}

/// Outlines `win` in white (over a dark border so it shows on bright images too).
fn outline(c: &mut [[u8; 3]], w: usize, h: usize, win: Window) {
    let mut set = |x: usize, y: usize, v: [u8; 3]| {
        if x < w && y < h {
            c[y * w + x] = v;
        }
    };
    let (x1, y1) = (win.x + win.w - 1, win.y + win.h - 1);
    for (d, v) in [(1usize, [0u8; 3]), (0, [255u8; 3])] {
        for x in win.x.saturating_sub(d)..=x1 + d {
            set(x, win.y.saturating_sub(d), v);
            set(x, y1 + d, v);
        }
        for y in win.y.saturating_sub(d)..=y1 + d {
            set(win.x.saturating_sub(d), y, v);
            set(x1 + d, y, v);
        }
    }
}

/// Mean of `v` over a window of a `w`-wide map.
fn window_mean(v: &[f64], w: usize, win: Window) -> f64 {
    let mut s = 0.0;
    for y in win.y..win.y + win.h {
        s += v[y * w + win.x..y * w + win.x + win.w].iter().sum::<f64>();
    }
    s / (win.w * win.h) as f64
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

/// A colour bar from 0 (bottom) to 1 (top), 24 px wide, `h` high.
fn colour_bar(h: u32, colour: impl Fn(f64) -> [u8; 3]) -> (Vec<u8>, (u32, u32)) {
    let mut out = Vec::with_capacity((24 * h * 3) as usize);
    for y in 0..h {
        let c = colour(1.0 - y as f64 / (h.max(2) - 1) as f64);
        for _ in 0..24 {
            out.extend(c);
        }
    }
    (out, (24, h))
}

/// Per-pixel relMSE (mean over channels) of tone-mapped colours against the reference's.
fn error_map(t: &[[f64; 3]], reference: &[[f64; 3]]) -> Vec<f64> {
    t.iter().zip(reference).map(|(x, y)| (0..3).map(|c| (x[c] - y[c]).powi(2) / (y[c] * y[c] + metrics::REL_MSE_EPS)).sum::<f64>() / 3.0).collect()
}

/// Images, error maps and W_G maps of one (scene, spp): whole frames on the first row, on the
/// second the same window of each enlarged ZOOM× — the window where the denoised images' mean
/// error is largest, outlined on the frames.
pub fn write_pictures(dir: &Path, p: &PictureData) -> Result<()> {
    let [images_png, errors_png, weights_png] = eval::picture_paths(dir, &p.scene, p.spp);
    let (w, h) = (p.width, p.height);
    let tile = (w as u32, h as u32);
    let mut ordered: Vec<&(String, String, Vec<f32>, f64)> = Vec::new();
    for name in PICTURE_METHODS {
        ordered.extend(p.images.iter().filter(|i| i.0 == name));
    }
    let reference = tonemapped(&p.reference);
    let toned: Vec<Vec<[f64; 3]>> = ordered.iter().map(|i| tonemapped(&i.2)).collect();
    let errors: Vec<Vec<f64>> = toned.iter().map(|t| error_map(t, &reference)).collect();
    // The zoom goes where the denoised images differ most visibly from the reference: squared
    // error of the displayed (tone-mapped) colours, which unlike relMSE does not single out the
    // darkest corner.
    let shown: Vec<&Vec<[f64; 3]>> = ordered.iter().zip(&toned).filter(|(i, _)| i.0 != "noisy").map(|(_, t)| t).collect();
    let score: Vec<f64> = (0..w * h).map(|i| shown.iter().map(|t| (0..3).map(|c| (t[i][c] - reference[i][c]).powi(2)).sum::<f64>()).sum()).collect();
    let win = hardest_window(&score, w, h);
    let zoom_label = format!("{ZOOM}× zoom");
    let to8 = |t: &[[f64; 3]]| -> Vec<[u8; 3]> { t.iter().map(|c| c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8)).collect() };
    let mapped = |v: &[f64], colour: &dyn Fn(f64) -> [u8; 3]| -> Vec<[u8; 3]> { v.iter().map(|&x| colour(x)).collect() };
    // Frame on row 0 (window outlined), zoom on row 1.
    let both_rows = |sheet: &mut Sheet, col: usize, mut c: Vec<[u8; 3]>, label: &str, sub: &str, zoom_sub: &str| {
        let (z, zs) = zoomed(&c, w, win);
        outline(&mut c, w, h, win);
        sheet.put(0, col, &rgb8(&c), tile, label, sub);
        sheet.put(1, col, &z, zs, &zoom_label, zoom_sub);
    };

    let mut sheet = Sheet::new(ordered.len() + 1, 2, tile);
    for (k, ((_, label, _, rel), t)) in ordered.iter().zip(&toned).enumerate() {
        both_rows(&mut sheet, k, to8(t), label, &format!("{rel:.4}"), &format!("{:.4}", window_mean(&errors[k], w, win)));
    }
    both_rows(&mut sheet, ordered.len(), to8(&reference), "reference", "8000 spp", "");
    sheet.save(&images_png)?;

    let mut sheet = Sheet::new(ordered.len() + 1, 2, tile);
    for (k, (_, label, _, rel)) in ordered.iter().enumerate() {
        both_rows(&mut sheet, k, mapped(&errors[k], &inferno_log), label, &format!("relMSE {rel:.4}"), &format!("{:.4}", window_mean(&errors[k], w, win)));
    }
    let (bar, bs) = colour_bar(tile.1, |t| inferno_log(10f64.powf(4.0 * t - 4.0)));
    sheet.put(0, ordered.len(), &bar, bs, "scale", "10⁻⁴ to 1");
    sheet.save(&errors_png)?;

    let mut sheet = Sheet::new(3, 2, tile);
    match &p.weights_g {
        Some(m) => {
            for (k, (v, name)) in [(&m.diffuse, "W_G diffuse"), (&m.specular, "W_G specular")].into_iter().enumerate() {
                let v: Vec<f64> = v.iter().map(|&x| x as f64).collect();
                both_rows(&mut sheet, k, mapped(&v, &viridis), name, "guided", &format!("mean {:.2}", window_mean(&v, w, win)));
            }
        }
        None => {
            let blank = vec![24u8; w * h * 3];
            sheet.put(0, 0, &blank, tile, "no guided", "model");
        }
    }
    let (bar, bs) = colour_bar(tile.1, viridis);
    sheet.put(0, 2, &bar, bs, "scale", "0 to 1");
    sheet.save(&weights_png)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hardest_window_finds_the_hot_spot() {
        let (w, h) = (30, 21);
        let mut score = vec![0.01; w * h];
        // A hot 4×4 block at (20, 12): the 10×7 window must contain it whole.
        for y in 12..16 {
            for x in 20..24 {
                score[y * w + x] = 5.0;
            }
        }
        score[0] = f64::NAN;
        let win = hardest_window(&score, w, h);
        assert_eq!((win.w, win.h), (10, 7));
        assert!(win.x <= 20 && win.x + win.w >= 24 && win.y <= 12 && win.y + win.h >= 16, "{win:?}");
        // Brute force agrees on the best sum.
        let sum = |x: usize, y: usize| (y..y + 7).map(|yy| score[yy * w + x..yy * w + x + 10].iter().filter(|v| v.is_finite()).sum::<f64>()).sum::<f64>();
        let best = (0..=h - 7).flat_map(|y| (0..=w - 10).map(move |x| (x, y))).map(|(x, y)| sum(x, y)).fold(f64::MIN, f64::max);
        assert!((sum(win.x, win.y) - best).abs() < 1e-9);
        assert!((window_mean(&score, w, win) - best / 70.0).abs() < 1e-12);
    }

    #[test]
    fn zoom_repeats_pixels_and_outline_stays_inside() {
        let (w, h) = (6, 6);
        let c: Vec<[u8; 3]> = (0..w * h).map(|i| [i as u8, 0, 0]).collect();
        let win = Window { x: 2, y: 3, w: 2, h: 2 };
        let (z, size) = zoomed(&c, w, win);
        assert_eq!(size, (6, 6));
        assert_eq!(z[0], 20); // pixel (2, 3)
        assert_eq!(z[(5 * 6 + 5) * 3], 27); // pixel (3, 4)
        assert_eq!(z[(2 * 6 + 3) * 3], 21); // pixel (3, 3): x 3 → source column 3
        let mut o = c.clone();
        outline(&mut o, w, h, Window { x: 0, y: 0, w: 6, h: 6 });
        assert_eq!(o[0], [255; 3]);
        assert_eq!(o[2 * 6 + 2], c[2 * 6 + 2]);
    }
}
