//! docs/results.md and its plots, from the measurements of `pixguide eval`; the pictures it
//! shows are drawn by pictures.rs, the sections on the bounds, the spread over render seeds and
//! the experts' weights by spread.rs.

use super::cache::{key, Record};
use super::methods::{EvalMethod, MethodSpec, BREAKDOWN_METHODS};
use super::oracle::BLOCK;
use super::pictures::ZOOM;
use super::scenes::TestScene;
use super::{picture_paths, picture_scenes, EvalArgs, Outcome, NORM_SPP};
use crate::cli::eval_plot::{self, Curve};
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;

pub(super) fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Which value of a record a table or plot shows.
#[derive(Clone, Copy)]
pub(super) enum Metric {
    RelMse,
    Ssim,
}

impl Metric {
    pub(super) fn of(self, r: &Record) -> f64 {
        match self {
            Metric::RelMse => r.rel_mse,
            Metric::Ssim => r.one_minus_ssim,
        }
    }
    pub(super) fn name(self) -> &'static str {
        match self {
            Metric::RelMse => "relMSE",
            Metric::Ssim => "1−SSIM",
        }
    }
}

/// A row of the tables: a method, or a block-oracle bound over some methods' outputs.
pub(super) struct Row<'a> {
    /// Name in the cache keys.
    pub name: &'a str,
    pub label: String,
    /// Label in plots.
    pub short: String,
    /// Identity of the weights the records were measured with.
    pub id: &'a str,
    pub bound: bool,
    pub missing: Option<&'a str>,
}

/// Every method (available or not), then every bound.
pub(super) fn rows(o: &Outcome) -> Vec<Row<'_>> {
    let mut out: Vec<Row> = o
        .methods
        .iter()
        .map(|m| Row {
            name: m.name(),
            label: m.label().into(),
            short: m.label().into(),
            id: &m.id,
            bound: false,
            missing: m.missing.as_deref(),
        })
        .collect();
    out.extend(o.bounds.iter().map(|b| Row {
        name: &b.name,
        label: b.label(),
        short: b.short_label(),
        id: &b.id,
        bound: true,
        missing: None,
    }));
    out
}

pub(super) struct View<'a> {
    pub a: &'a EvalArgs,
    pub o: &'a Outcome,
}

impl View<'_> {
    pub(super) fn rec(&self, scene: &TestScene, spp: u32, r: &Row, seed: u64) -> Option<&Record> {
        self.o.records.get(&key("quality", &scene.name, &scene.reference_id, spp, r.name, r.id, seed, scene.width, scene.height))
    }
    fn noisy(&self) -> &MethodSpec {
        &self.o.methods[0]
    }
    /// The scene's error normalised by its 2-spp noisy error of the same seed.
    fn norm(&self, scene: &TestScene, spp: u32, r: &Row, metric: Metric, seed: u64) -> Option<f64> {
        let n = self.noisy();
        let base = metric.of(self.o.quality(&scene.name, NORM_SPP, n, seed, scene)?);
        let v = metric.of(self.rec(scene, spp, r, seed)?);
        (base > 0.0).then(|| v / base)
    }
    /// Mean over scenes of the raw and of the normalised value at one seed (scenes lacking it
    /// are left out).
    fn seed_means(&self, spp: u32, r: &Row, metric: Metric, seed: u64) -> (Option<f64>, Option<f64>) {
        let raw: Vec<f64> = self.o.scenes.iter().filter_map(|s| self.rec(s, spp, r, seed).map(|x| metric.of(x))).collect();
        let norm: Vec<f64> = self.o.scenes.iter().filter_map(|s| self.norm(s, spp, r, metric, seed)).collect();
        (mean(&raw), mean(&norm))
    }
    /// [`Self::seed_means`] averaged over the seeds that have it.
    fn means(&self, spp: u32, r: &Row, metric: Metric) -> (Option<f64>, Option<f64>) {
        let per: Vec<(Option<f64>, Option<f64>)> = self.a.seeds.iter().map(|&seed| self.seed_means(spp, r, metric, seed)).collect();
        (mean(&per.iter().filter_map(|p| p.0).collect::<Vec<_>>()), mean(&per.iter().filter_map(|p| p.1).collect::<Vec<_>>()))
    }
    /// Mean over scenes at each seed, only where every scene has it (so that seeds compare).
    pub(super) fn complete_seed_means(&self, spp: u32, r: &Row, metric: Metric) -> Vec<Option<f64>> {
        self.a
            .seeds
            .iter()
            .map(|&seed| {
                let v: Option<Vec<f64>> = self.o.scenes.iter().map(|s| self.rec(s, spp, r, seed).map(|x| metric.of(x))).collect();
                mean(&v?)
            })
            .collect()
    }
    /// One scene's raw and normalised value, each averaged over the seeds that have it.
    fn scene_means(&self, scene: &TestScene, spp: u32, r: &Row, metric: Metric) -> (Option<f64>, Option<f64>) {
        let raw: Vec<f64> = self.a.seeds.iter().filter_map(|&seed| self.rec(scene, spp, r, seed).map(|x| metric.of(x))).collect();
        let norm: Vec<f64> = self.a.seeds.iter().filter_map(|&seed| self.norm(scene, spp, r, metric, seed)).collect();
        (mean(&raw), mean(&norm))
    }
    fn mean_time(&self, spp: u32, r: &Row) -> Option<f64> {
        let t: Vec<f64> = self
            .a
            .seeds
            .iter()
            .flat_map(|&seed| self.o.scenes.iter().filter_map(move |s| self.rec(s, spp, r, seed).map(|x| x.time_s)))
            .collect();
        mean(&t)
    }
}

pub(super) fn f(v: Option<f64>, digits: usize) -> String {
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
    let all = rows(o);
    // Rows with measurements: the available methods and the bounds.
    let avail: Vec<&Row> = all.iter().filter(|r| r.missing.is_none()).collect();
    let timed: Vec<&Row> = avail.iter().copied().filter(|r| !r.bound).collect();
    let seeds = a.seeds.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ");
    let mut spps = a.spp.clone();
    spps.sort_unstable();
    spps.dedup();
    let (cores, cpu) = machine();
    let mut s = String::new();
    let w = &mut s;
    writeln!(w, "# Results: error against samples and against time\n")?;
    writeln!(w, "*Written by `pixguide eval` from its own measurements; regenerate it with the command below rather than editing it.*\n")?;
    writeln!(w, "- **command**: `{}`", command_line())?;
    writeln!(w, "- **date**: {} · **commit**: {}", crate::cli::train::iso_date_utc(), {
        let c = crate::cli::train::git_commit();
        if c.is_empty() {
            "unknown".into()
        } else {
            c
        }
    })?;
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
        "Each test scene of `{}` ({}) is rendered at its reference's size with {} at {} spp and scored against its 8000-spp reference \
         (`references/` beside the list). relMSE = mean over pixels and channels of (x−y)²/(y²+10⁻⁴) and 1−SSIM (7×7 uniform window, data range 1), both after \
         tone map (a) of method.md §7.3 (c/(1+lum(c)/1.5), then ^(1/2.2), clipped), over the whole image (no border crop: tiled inference mirror-pads the \
         image, so border pixels are denoised too) — the numbers `pixguide render --reference` prints. **norm.** = the value divided by the same scene's \
         {NORM_SPP}-spp noisy error, then averaged over scenes (the paper's Table 2 convention, method.md §7.3).\n",
        a.scenes.display(),
        o.scenes.iter().map(|s| format!("{} {}×{}", s.name, s.width, s.height)).collect::<Vec<_>>().join(", "),
        if a.seeds.len() == 1 { format!("seed {seeds}") } else { format!("each of the render seeds {seeds}") },
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
        crate::cli::oidn_setup::PACKAGE
    )?;
    if a.seeds.len() > 1 {
        writeln!(
            w,
            "With {} render seeds, every value below is the mean over the seeds of the value at each seed (a mean over scenes, or one \
             scene's); the section on the spread over seeds gives how much it varies from one seed to the next.\n",
            a.seeds.len()
        )?;
    }
    writeln!(
        w,
        "**Bounds** (rows and curves named *bound*) are not methods: they use the reference. For each {BLOCK}×{BLOCK} block of the image \
         (the last ones cut by its edge) a bound keeps the pixels of whichever of its experts' outputs has the lower error against the \
         reference over that block — the error being this page's relMSE (after tone map (a)) restricted to the block; ties go to the \
         expert listed first — and the image so assembled is scored like every method, relMSE and 1−SSIM over the whole image. It \
         says how much a per-pixel choice among those outputs, such as the guided model's E makes, could gain at most at that \
         granularity. The choice minimises relMSE, not 1−SSIM: the seams between blocks from different experts can make a bound's \
         1−SSIM higher than that of its best expert.\n"
    )?;
    writeln!(w, "| method | weights | status |\n|---|---|---|")?;
    for m in &o.methods {
        let file = match (&m.file, m.kind) {
            (Some(p), _) => format!("`{}`", p.display()),
            (None, EvalMethod::Oidn) => "its own, built into the library".into(),
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
            (None, None, Some(o)) => crate::cli::oidn_setup::describe(o),
            (None, None, None) => "plain Monte Carlo, no denoising".into(),
        };
        writeln!(w, "| {} | {file} | {status} |", m.label())?;
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
        for m in &all {
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

    super::spread::write(w, &v, &all)?;

    // Plots (the bounds on the spp plot only: they take no time of their own).
    let curves = |metric: Metric, by_time: bool| -> Vec<Curve> {
        avail
            .iter()
            .enumerate()
            .filter(|(_, m)| !(by_time && m.bound))
            .map(|(k, m)| Curve {
                label: m.short.clone(),
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
    eval_plot::write_pair(
        &spp_png,
        "samples per pixel",
        Some(spps.iter().map(|&s| s as f64).collect()),
        ("relMSE / 2-spp noisy", &curves(Metric::RelMse, false)),
        ("1 − SSIM / 2-spp noisy", &curves(Metric::Ssim, false)),
    )?;
    eval_plot::write_pair(
        &time_png,
        "seconds (render + denoise)",
        None,
        ("relMSE / 2-spp noisy", &curves(Metric::RelMse, true)),
        ("1 − SSIM / 2-spp noisy", &curves(Metric::Ssim, true)),
    )?;
    writeln!(w, "\n## Error against samples per pixel and against time\n")?;
    writeln!(
        w,
        "Mean normalised error, log-log; one curve per method, plain Monte Carlo included (the paper's Fig. 4 and Fig. 10), and on the \
         error-against-spp plot the bounds, which use the reference.\n"
    )?;
    writeln!(w, "![error vs spp]({rel}/error-vs-spp.png)\n\n![error vs time]({rel}/error-vs-time.png)\n")?;
    writeln!(w, "Mean time per image (seconds: render + preprocessing + inference):\n")?;
    write!(w, "| method |")?;
    for spp in &spps {
        write!(w, " {spp} spp |")?;
    }
    writeln!(w, "\n|---|{}", "---|".repeat(spps.len()))?;
    for m in &timed {
        write!(w, "| {} |", m.label)?;
        for &spp in &spps {
            write!(w, " {} |", f(v.mean_time(spp, m), 2))?;
        }
        writeln!(w)?;
    }

    // Breakdown.
    writeln!(w, "\n## Runtime breakdown (the paper's Table 1)\n")?;
    let asked: Vec<&MethodSpec> = BREAKDOWN_METHODS.iter().filter_map(|n| o.methods.iter().find(|m| m.kind == *n)).collect();
    if a.breakdown_size == 0 || asked.is_empty() {
        writeln!(w, "Not measured (`--breakdown-size 0`, or neither guided nor oidn among `--methods`).")?;
    }
    for m in asked.iter().filter(|m| a.breakdown_size > 0 && !m.available()) {
        writeln!(w, "{}: not available ({}).\n", m.label(), m.missing.clone().unwrap_or_default())?;
    }
    let shown: Vec<&&MethodSpec> = asked.iter().filter(|m| a.breakdown_size > 0 && m.available()).collect();
    if !shown.is_empty() {
        let size = a.breakdown_size;
        writeln!(
            w,
            "Wall seconds on {1} rendered at {size}×{size} (the first seed), for {0}. The guided model renders with descriptors; D_P includes the path-manifold modules; \
             E + blend includes recombining the two branches; tiling = cutting windows out of the prepared image and reading results back; columns \
             of the two branches (diffuse, specular) are summed. OIDN renders without descriptors; its filter = OIDN's RT filter, commit + execute.\n",
            shown.iter().map(|m| m.label()).collect::<Vec<_>>().join(" and "),
            o.breakdown_scene
        )?;
        writeln!(w, "| spp | method | render | preprocessing | D_G | D_P (with path module) | E + blend | tiling | OIDN filter | total |\n|---|---|---|---|---|---|---|---|---|---|")?;
        for &spp in &spps {
            for m in &shown {
                let found = o.records.values().find(|r| {
                    r.kind == "breakdown"
                        && r.method == m.name()
                        && r.scene == o.breakdown_scene
                        && r.spp == spp
                        && r.weights == m.id
                        && r.seed == a.seeds[0]
                        && r.width == size
                        && r.height == size
                });
                let Some(r) = found else { continue };
                if m.oidn.is_some() {
                    writeln!(
                        w,
                        "| {spp} | {} | {:.2} | – | – | – | – | – | {:.2} | {:.2} |",
                        m.label(),
                        r.render_s,
                        r.denoise_s,
                        r.time_s
                    )?;
                } else {
                    writeln!(
                        w,
                        "| {spp} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | – | {:.2} |",
                        m.label(),
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
    writeln!(
        w,
        "Each cell: raw error (normalised by the scene's {NORM_SPP}-spp noisy error). The mean row averages each over the scenes. \
         Bounds use the reference.\n"
    )?;
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
                    let (raw, norm) = v.scene_means(sc, spp, m, metric);
                    write!(w, " {} ({}) |", f(raw, 4), f(norm, 3))?;
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
    let pics = picture_scenes(a, &o.scenes);
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
                let [i, e, wg] = picture_paths(dir, p, spp).map(|x| x.file_name().unwrap().to_string_lossy().into_owned());
                writeln!(w, "### {p}, {spp} spp\n\n![{p} {spp} spp]({rel}/{i})\n\n![errors]({rel}/{e})\n\n![W_G]({rel}/{wg})\n")?;
            }
        }
    }
    crate::cli::denoise::ensure_parent(&a.out)?;
    std::fs::write(&a.out, s).with_context(|| format!("writing {}", a.out.display()))?;
    Ok(())
}
