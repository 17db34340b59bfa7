//! `pixguide plot-training`: validation curves of training runs, read from the
//! `<weights>.log.jsonl` files `pixguide train` writes, drawn against steps and against wall time,
//! with a Markdown summary (best validation, where the curve flattens) on stdout.

use super::eval_plot::{self, Canvas, AXIS_SIZE, CAPTION_SIZE, TICK_SIZE};
use super::font;
use super::val_baselines::{self, Baseline};
use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use denoiser::model::Preset;
use plotters::coord::Shift;
use plotters::prelude::*;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A validation counts as an improvement on an earlier one only if it is this much lower
/// (relative): smaller changes are within the run-to-run noise of the short runs we can afford.
const FLAT_TOLERANCE: f64 = 0.05;

#[derive(Args)]
pub struct PlotTrainingArgs {
    /// Training logs (`<weights>.log.jsonl`, written by `pixguide train`); one curve each.
    #[arg(required = true)]
    pub logs: Vec<PathBuf>,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Curve labels, in the order of the logs (default: each file's name without
    /// `.safetensors.log.jsonl`).
    #[arg(long, value_delimiter = ',')]
    pub labels: Option<Vec<String>>,
    /// Title above both panels.
    #[arg(long, default_value = "Validation relMSE during training")]
    pub title: String,
    /// Dataset the runs validated on: the noisy input and OIDN (installed on first use, as for
    /// `pixguide eval`) are scored on its validation shots with the runs' own measure and drawn as
    /// dashed lines.
    #[arg(long)]
    pub baselines: Option<PathBuf>,
    /// With --baselines: the runs' network preset (its margin is cropped from every window).
    #[arg(long, default_value = "edge-noise")]
    pub preset: Preset,
    /// With --baselines: the runs' patch side (`pixguide train --patch`).
    #[arg(long, default_value_t = 96)]
    pub patch: usize,
    /// With --baselines: the noisy input only, without OIDN.
    #[arg(long)]
    pub no_oidn: bool,
}

/// (samples per pixel, relMSE at that count) pairs of one validation.
type BySpp = Vec<(usize, f64)>;

/// A validation as the log states it, before its wall time is settled.
struct Logged {
    total_step: usize,
    rel_mse: f64,
    /// Wall seconds, when the log has them.
    seconds: Option<f64>,
    /// Step durations summed up to this validation.
    step_seconds: f64,
    by_spp: BySpp,
}

/// One validation of a run.
#[derive(Clone, Debug, PartialEq)]
struct Val {
    step: usize,
    rel_mse: f64,
    minutes: f64,
    /// Empty in logs written before training logged it.
    by_spp: BySpp,
}

/// What a log says about its run.
#[derive(Debug)]
struct Run {
    /// Finite validations in training order.
    vals: Vec<Val>,
    steps: usize,
    minutes: f64,
    /// The log's validations carry no wall time (logs written before they did): the minutes are
    /// the summed step durations, so they leave out the time spent validating.
    time_from_steps: bool,
}

impl Run {
    fn best(&self) -> usize {
        let mut b = 0;
        for (i, v) in self.vals.iter().enumerate() {
            if v.rel_mse < self.vals[b].rel_mse {
                b = i;
            }
        }
        b
    }

    fn flattens(&self) -> Option<usize> {
        flatten_index(&self.vals.iter().map(|v| v.rel_mse).collect::<Vec<_>>(), FLAT_TOLERANCE)
    }
}

/// Index of the first value that no later value improves on by more than `tol` (relative), or
/// None if that is only the last one: the curve was still falling when the run ended (or had a
/// single validation, which says nothing about its slope).
fn flatten_index(v: &[f64], tol: f64) -> Option<usize> {
    let i = (0..v.len()).find(|&i| v[i + 1..].iter().all(|&later| later >= v[i] * (1.0 - tol)))?;
    (i + 1 < v.len()).then_some(i)
}

/// Curve label of a log: its file name without `.jsonl`, `.log` and `.safetensors`.
fn default_label(path: &Path) -> String {
    let mut name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| path.display().to_string());
    for suffix in [".jsonl", ".log", ".safetensors"] {
        if let Some(s) = name.strip_suffix(suffix) {
            name = s.to_string();
        }
    }
    name
}

fn field_u64(v: &Value, key: &str, what: &str) -> Result<u64> {
    v.get(key).and_then(Value::as_u64).ok_or_else(|| anyhow!("{what} event without a whole-number \"{key}\""))
}

fn field_f64(v: &Value, key: &str, what: &str) -> Result<f64> {
    v.get(key).and_then(Value::as_f64).ok_or_else(|| anyhow!("{what} event without a numeric \"{key}\""))
}

/// Reads a training log; `name` (the file) is named in every error, with the line number where
/// there is one.
fn parse_log(name: &str, text: &str) -> Result<Run> {
    let mut vals: Vec<Logged> = Vec::new();
    let mut step_seconds = 0.0;
    let mut stage_steps: BTreeMap<u64, u64> = BTreeMap::new();
    let mut lines = 0;
    for (k, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        lines += 1;
        let at = || format!("{name}, line {}", k + 1);
        let v: Value = serde_json::from_str(line).map_err(|e| {
            // serde's own position says "line 1" (of this one line): give the column only.
            let msg = e.to_string();
            anyhow!("{}, column {}: not valid JSON ({})", at(), e.column(), msg.split(" at line ").next().unwrap_or(&msg))
        })?;
        let event = v
            .get("event")
            .and_then(Value::as_str)
            .ok_or_else(|| anyhow!("{}: no \"event\" field (is this a `pixguide train` log?)", at()))?;
        match event {
            "step" => {
                let (stage, step) = (field_u64(&v, "stage", "step").with_context(at)?, field_u64(&v, "step", "step").with_context(at)?);
                step_seconds += field_f64(&v, "seconds", "step").with_context(at)?;
                let s = stage_steps.entry(stage).or_default();
                *s = (*s).max(step);
            }
            "val" => {
                let total = field_u64(&v, "total_step", "val").with_context(at)? as usize;
                // The trainer writes null for a non-finite relMSE.
                let rel_mse = match v.get("rel_mse") {
                    Some(Value::Null) => f64::NAN,
                    _ => field_f64(&v, "rel_mse", "val").with_context(at)?,
                };
                let seconds = match v.get("seconds") {
                    None => None,
                    Some(_) => Some(field_f64(&v, "seconds", "val").with_context(at)?),
                };
                let by_spp = match v.get("by_spp") {
                    None => Vec::new(),
                    Some(b) => serde_json::from_value::<Vec<(usize, Option<f64>)>>(b.clone())
                        .map_err(|e| anyhow!("{}: \"by_spp\" is not a list of [spp, relMSE] pairs ({e})", at()))?
                        .into_iter()
                        .map(|(n, r)| (n, r.unwrap_or(f64::NAN)))
                        .collect(),
                };
                // A run resumed from an older checkpoint repeats steps: its new validations
                // replace those of the abandoned continuation.
                while vals.last().is_some_and(|l| l.total_step >= total) {
                    vals.pop();
                }
                vals.push(Logged { total_step: total, rel_mse, seconds, step_seconds, by_spp });
            }
            _ => {}
        }
    }
    if lines == 0 {
        bail!("{name}: empty log (no events)");
    }
    if vals.is_empty() {
        bail!("{name}: no validation events in {lines} lines (did the run stop before its first validation?)");
    }
    let time_from_steps = vals.iter().any(|v| v.seconds.is_none());
    let seconds_at = |v: &Logged| if time_from_steps { v.step_seconds } else { v.seconds.unwrap_or(v.step_seconds) };
    let last = &vals[vals.len() - 1];
    // Steps trained after the last validation still count towards the run's length.
    let minutes = (seconds_at(last) + (step_seconds - last.step_seconds)) / 60.0;
    let steps = (stage_steps.values().sum::<u64>() as usize).max(last.total_step);
    let vals: Vec<Val> = vals
        .iter()
        .filter(|v| v.rel_mse.is_finite() && v.rel_mse > 0.0)
        .map(|v| Val { step: v.total_step, rel_mse: v.rel_mse, minutes: seconds_at(v) / 60.0, by_spp: v.by_spp.clone() })
        .collect();
    if vals.is_empty() {
        bail!("{name}: no validation with a finite, positive relMSE");
    }
    Ok(Run { vals, steps, minutes, time_from_steps })
}

pub fn run(a: PlotTrainingArgs) -> Result<()> {
    let labels = match &a.labels {
        Some(l) if l.len() != a.logs.len() => bail!("--labels has {} names for {} logs", l.len(), a.logs.len()),
        Some(l) => l.clone(),
        None => a.logs.iter().map(|p| default_label(p)).collect(),
    };
    let mut runs = Vec::with_capacity(a.logs.len());
    for path in &a.logs {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        runs.push(parse_log(&path.display().to_string(), &text)?);
    }
    let runs: Vec<(String, Run)> = labels.into_iter().zip(runs).collect();
    let baselines = match &a.baselines {
        None => Vec::new(),
        Some(data) => {
            let oidn = if a.no_oidn { None } else { Some(super::oidn_setup::load()?.0) };
            val_baselines::measure(data, a.patch, a.preset.config().margin(), oidn.as_ref())?
        }
    };
    draw(&a.output, &a.title, &runs, &baselines)?;
    print!("{}", table(&runs));
    print!("{}", by_spp_table(&runs, &baselines));
    eprintln!("wrote {}", a.output.display());
    Ok(())
}

/// relMSE with 4 significant digits.
fn sig4(v: f64) -> String {
    let decimals = (3 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    format!("{v:.decimals$}")
}

fn table(runs: &[(String, Run)]) -> String {
    let mut s = String::from(
        "| run | steps | wall min | best val relMSE | best at step | best at min | flattens at step (min): first val no later val beats by > 5 % |\n|---|---:|---:|---:|---:|---:|---:|\n",
    );
    for (label, r) in runs {
        let b = &r.vals[r.best()];
        let flat = match r.flattens() {
            Some(i) => format!("{} ({:.1})", r.vals[i].step, r.vals[i].minutes),
            None => "not yet".into(),
        };
        let mark = if r.time_from_steps { " *" } else { "" };
        s +=
            &format!("| {label}{mark} | {} | {:.1} | {} | {} | {:.1} | {flat} |\n", r.steps, r.minutes, sig4(b.rel_mse), b.step, b.minutes);
    }
    if runs.iter().any(|r| r.1.time_from_steps) {
        s += "\n\\* log without validation times: minutes are summed step durations and leave out validation.\n";
    }
    s
}

/// Each run's best validation split by sample count (runs whose log has the split), and the
/// baselines on the same measure: the issue's floors are per spp. Empty if there is neither.
fn by_spp_table(runs: &[(String, Run)], baselines: &[Baseline]) -> String {
    let mut rows: Vec<(String, f64, BySpp)> = Vec::new();
    for (label, r) in runs {
        let b = &r.vals[r.best()];
        if !b.by_spp.is_empty() {
            rows.push((format!("{label}, best (step {})", b.step), b.rel_mse, b.by_spp.clone()));
        }
    }
    rows.extend(baselines.iter().map(|b| (b.label.to_string(), b.overall, b.by_spp.clone())));
    let mut spps: Vec<usize> = rows.iter().flat_map(|r| r.2.iter().map(|v| v.0)).collect();
    spps.sort_unstable();
    spps.dedup();
    if rows.is_empty() {
        return String::new();
    }
    let mut s = format!(
        "\n| validation relMSE by spp | all | {} |\n|---|---:|{}\n",
        spps.iter().map(|n| format!("{n} spp")).collect::<Vec<_>>().join(" | "),
        "---:|".repeat(spps.len())
    );
    for (label, all, by) in rows {
        let cells: Vec<String> =
            spps.iter().map(|n| by.iter().find(|v| v.0 == *n).map_or_else(|| "–".to_string(), |v| sig4(v.1))).collect();
        s += &format!("| {label} | {} | {} |\n", sig4(all), cells.join(" | "));
    }
    s
}

/// Ticks of the log y axis over [lo, hi] and their decimals: evenly spaced round values when
/// the range is narrow (validation curves often span less than a factor 3, where 1-2-5 ticks
/// leave one or two labels), all with the same decimals; else log ticks (1-2-5 per decade,
/// finer if that gives few), each with as few decimals as it needs (None).
fn y_ticks(lo: f64, hi: f64) -> (Vec<f64>, Option<usize>) {
    if hi / lo >= 3.0 {
        return (eval_plot::ticks_at_least(lo, hi, 5), None);
    }
    let raw = (hi - lo) / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * mag).find(|&s| s >= raw).unwrap_or(10.0 * mag);
    let out: Vec<f64> = ((lo / step).ceil() as i64..=(hi / step).floor() as i64).map(|k| k as f64 * step).collect();
    (out, Some((-step.log10().floor()).max(0.0) as usize))
}

/// `v` to 3 significant digits without trailing zeros.
fn short(v: f64) -> String {
    let d = (2 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{v:.d$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// An axis label: whole numbers without decimals.
fn num(v: f64, decimals: usize) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        format!("{v:.decimals$}")
    }
}

/// y range of the curves: a 10 % margin on a log scale, at least a factor 1.5 wide.
fn y_range(runs: &[(String, Run)], baselines: &[Baseline]) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for v in runs.iter().flat_map(|r| &r.1.vals).map(|v| v.rel_mse).chain(baselines.iter().map(|b| b.overall)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    let widen = (1.5 / (hi / lo)).max(1.0).sqrt();
    (lo / 1.1 / widen, hi * 1.1 * widen)
}

fn panel(
    area: &DrawingArea<Canvas<'_>, Shift>,
    caption: &str,
    x_label: &str,
    runs: &[(String, Run)],
    baselines: &[Baseline],
    x_of: fn(&Val) -> f64,
) -> Result<()> {
    let err = |e: DrawingAreaErrorKind<std::io::Error>| anyhow!("plot: {e}");
    let x_max = runs.iter().flat_map(|r| &r.1.vals).map(x_of).fold(0.0, f64::max).max(1e-6) * 1.05;
    let (y0, y1) = y_range(runs, baselines);
    let (y_keys, y_dec) = y_ticks(y0, y1);
    let x_dec = if x_max < 3.0 {
        2
    } else if x_max < 30.0 {
        1
    } else {
        0
    };
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", CAPTION_SIZE))
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..x_max, (y0..y1).log_scale().with_key_points(y_keys))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc("validation relMSE")
        .x_labels(8)
        .label_style(("sans-serif", TICK_SIZE))
        .axis_desc_style(("sans-serif", AXIS_SIZE))
        .max_light_lines(1)
        .x_label_formatter(&|v| num(*v, x_dec))
        .y_label_formatter(&|v| y_dec.map_or_else(|| short(*v), |d| format!("{v:.d$}")))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(200, 200, 200))
        .draw()
        .map_err(err)?;
    for (i, (_, r)) in runs.iter().enumerate() {
        let col = eval_plot::colour(i);
        let pts: Vec<(f64, f64)> = r.vals.iter().map(|v| (x_of(v), v.rel_mse)).collect();
        chart.draw_series(LineSeries::new(pts.clone(), col.stroke_width(2))).map_err(err)?;
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, col.filled()))).map_err(err)?;
        chart.draw_series(std::iter::once(Circle::new(pts[r.best()], 8, col.stroke_width(2)))).map_err(err)?;
    }
    for (i, b) in baselines.iter().enumerate() {
        let col = eval_plot::colour(runs.len() + i);
        chart.draw_series(DashedLineSeries::new([(0.0, b.overall), (x_max, b.overall)], 10, 6, col.stroke_width(2))).map_err(err)?;
    }
    Ok(())
}

const TITLE_H: u32 = 34;
const TITLE_SIZE: f32 = 22.0;
const NOTE_H: u32 = 18;
const NOTE_SIZE: f32 = 14.0;

fn draw(path: &Path, title: &str, runs: &[(String, Run)], baselines: &[Baseline]) -> Result<()> {
    let (w, plot_h) = (1100u32, 440u32);
    let mut legend_labels: Vec<String> = runs.iter().map(|(l, r)| if r.time_from_steps { format!("{l} *") } else { l.clone() }).collect();
    legend_labels.extend(baselines.iter().map(|b| format!("{} (dashed)", b.label)));
    let entries: Vec<(usize, &str)> = legend_labels.iter().enumerate().map(|(i, l)| (i, l.as_str())).collect();
    let legend_h = eval_plot::legend_height(&entries, w);
    let mut notes = vec!["Rings: the best validation of each run.".to_string()];
    if !baselines.is_empty() {
        notes.push("Dashed: the noisy input and OIDN on the same validation windows, scored as the runs are.".into());
    }
    if runs.iter().any(|r| r.1.time_from_steps) {
        notes.push("* Minutes exclude validation: the log has no validation times, so they are its summed step durations.".into());
    }
    let h = TITLE_H + plot_h + legend_h + notes.len() as u32 * NOTE_H + 6;
    let mut px = vec![255u8; (w * h * 3) as usize];
    {
        let root = DrawingArea::from(Canvas::new(&mut px, w, h));
        let (_, below_title) = root.split_vertically(TITLE_H);
        let (plots, _) = below_title.split_vertically(plot_h);
        let halves = plots.split_evenly((1, 2));
        panel(&halves[0], "against training steps", "total steps", runs, baselines, |v| v.step as f64)?;
        panel(&halves[1], "against wall time", "wall-clock minutes", runs, baselines, |v| v.minutes)?;
    }
    let title_w = font::text_size(title, TITLE_SIZE).0;
    font::draw(&mut px, w, (w.saturating_sub(title_w) / 2, 8), w, TITLE_SIZE, [20, 20, 20], title);
    eval_plot::draw_legend(&mut px, w, TITLE_H + plot_h, &entries);
    for (k, note) in notes.iter().enumerate() {
        font::draw(&mut px, w, (12, TITLE_H + plot_h + legend_h + k as u32 * NOTE_H + 2), w, NOTE_SIZE, [90, 90, 90], note);
    }
    super::shared::ensure_parent(path)?;
    renderer::film::png::write_rgb8(path, w, h, px)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flatten_is_the_first_validation_no_later_one_beats_by_more_than_the_tolerance() {
        // 0.030 → 0.029 is 3.3 % better: within 5 %, so the curve is flat from 0.030 on.
        assert_eq!(flatten_index(&[0.1, 0.05, 0.03, 0.029, 0.0295], 0.05), Some(2));
        // Still falling by more than 5 % at the end: only the last qualifies, so not yet.
        assert_eq!(flatten_index(&[0.2, 0.1, 0.05], 0.05), None);
        assert_eq!(flatten_index(&[0.04], 0.05), None);
        // A later spike does not undo flatness, a later 6 % improvement does.
        assert_eq!(flatten_index(&[0.05, 0.08, 0.049], 0.05), Some(0));
        assert_eq!(flatten_index(&[0.05, 0.08, 0.047, 0.047], 0.05), Some(2));
    }

    #[test]
    fn old_logs_take_time_from_steps_and_resumes_replace_abandoned_validations() {
        let log = r#"{"event":"stage","stage":0,"kind":"branches","steps":4}
{"event":"step","stage":0,"step":1,"loss":0.5,"seconds":30}
{"event":"step","stage":0,"step":2,"loss":0.4,"seconds":30}
{"event":"val","stage":0,"step":2,"total_step":2,"rel_mse":0.2,"best":true}
{"event":"step","stage":0,"step":3,"loss":0.4,"seconds":30}
{"event":"val","stage":0,"step":3,"total_step":3,"rel_mse":0.3,"best":false}
{"event":"step","stage":0,"step":3,"loss":0.4,"seconds":30}
{"event":"val","stage":0,"step":3,"total_step":3,"rel_mse":0.1,"best":true}
{"event":"step","stage":0,"step":4,"loss":0.4,"seconds":30}
"#;
        let r = parse_log("x", log).unwrap();
        assert!(r.time_from_steps);
        assert_eq!(
            r.vals,
            vec![
                Val { step: 2, rel_mse: 0.2, minutes: 1.0, by_spp: Vec::new() },
                Val { step: 3, rel_mse: 0.1, minutes: 2.0, by_spp: Vec::new() }
            ]
        );
        assert_eq!((r.steps, r.minutes), (4, 2.5));
        assert_eq!(r.best(), 1);
    }

    #[test]
    fn validations_split_by_spp_reach_the_table_beside_the_baselines() {
        let log = r#"{"event":"step","stage":0,"step":1,"loss":0.5,"seconds":1}
{"event":"val","stage":0,"step":1,"total_step":1,"rel_mse":0.3,"by_spp":[[2,0.5],[8,0.1]],"best":true,"seconds":60}
{"event":"val","stage":0,"step":2,"total_step":2,"rel_mse":0.2,"by_spp":[[2,0.3],[8,null]],"best":true,"seconds":120}
"#;
        let r = parse_log("x", log).unwrap();
        assert_eq!(r.vals[0].by_spp, vec![(2, 0.5), (8, 0.1)]);
        assert!(r.vals[1].by_spp[1].1.is_nan());
        let runs = vec![("g".to_string(), r)];
        let base = [Baseline { label: "OIDN", overall: 0.25, by_spp: vec![(2, 0.4), (4, 0.2)] }];
        let t = by_spp_table(&runs, &base);
        assert!(t.contains("| all | 2 spp | 4 spp | 8 spp |"), "{t}");
        // The best validation (step 2), its 4-spp cell missing; OIDN without 8 spp.
        assert!(t.contains("| g, best (step 2) | 0.2000 | 0.3000 | – | NaN |"), "{t}");
        assert!(t.contains("| OIDN | 0.2500 | 0.4000 | 0.2000 | – |"), "{t}");
        assert!(parse_log("y", &log.replace("[[2,0.5],[8,0.1]]", "7")).unwrap_err().to_string().contains("y, line 2"));
    }
}
