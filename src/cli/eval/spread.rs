//! The results page's sections on the headroom and the spread over render seeds: each row's mean
//! error with its spread over seeds, every row's ratio to min(g, p) and to OIDN with the spread
//! of that ratio, and the experts' mean weights (a guided model's W, a bound's share of pixels).

use super::report::{f, mean, Metric, Row, View};
use std::fmt::Write as _;

/// A record's mean weight per expert, by expert name.
type Weights = Vec<(String, f64)>;

/// Mean, standard error of the mean (sample standard deviation / √n; 0 for one value), min, max.
fn stats(v: &[f64]) -> Option<(f64, f64, f64, f64)> {
    let m = mean(v)?;
    let n = v.len() as f64;
    let sem = if v.len() > 1 { (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt() / n.sqrt() } else { 0.0 };
    let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    Some((m, sem, lo, hi))
}

/// "mean ± SEM [min–max]", or the value alone for one seed.
fn cell(v: &[f64], digits: usize) -> String {
    match stats(v) {
        None => "–".into(),
        Some((m, _, _, _)) if v.len() == 1 => format!("{m:.digits$}"),
        Some((m, sem, lo, hi)) => format!("{m:.digits$} ± {sem:.digits$} [{lo:.digits$}–{hi:.digits$}]"),
    }
}

pub(super) fn write(w: &mut String, v: &View, rows: &[Row]) -> std::fmt::Result {
    let (a, o) = (v.a, v.o);
    let mut spps = a.spp.clone();
    spps.sort_unstable();
    spps.dedup();
    let avail: Vec<&Row> = rows.iter().filter(|r| r.missing.is_none()).collect();
    let n = a.seeds.len();
    let header = |w: &mut String, first: &str| -> std::fmt::Result {
        write!(w, "| {first} |")?;
        for spp in &spps {
            write!(w, " {spp} spp |")?;
        }
        writeln!(w, "\n|---|{}", "---|".repeat(spps.len()))
    };

    writeln!(w, "\n## Headroom and the spread over render seeds\n")?;
    if n == 1 {
        writeln!(
            w,
            "One render seed ({}): no spread. `pixguide eval --seeds 4242,4243,4244` renders every (scene, spp) at each seed and \
             gives here the spread of every number over the seeds.\n",
            a.seeds[0]
        )?;
    } else {
        writeln!(
            w,
            "Each cell: the mean over the {n} render seeds ({}) of the mean over the {} scenes, ± its standard error over the seeds \
             (sample standard deviation / √{n}), [smallest–largest seed]. Only seeds at which every scene was measured count.\n",
            a.seeds.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", "),
            o.scenes.len()
        )?;
    }
    for metric in [Metric::RelMse, Metric::Ssim] {
        writeln!(w, "Mean {} over the scenes:\n", metric.name())?;
        header(w, "method")?;
        for r in &avail {
            write!(w, "| {} |", r.label)?;
            for &spp in &spps {
                let per: Vec<f64> = v.complete_seed_means(spp, r, metric).into_iter().flatten().collect();
                write!(w, " {} |", cell(&per, 4))?;
            }
            writeln!(w)?;
        }
        writeln!(w)?;
    }

    // Ratios, seed by seed: both errors come from the same noisy images, so the ratio varies far
    // less over seeds than either error does.
    let by_name = |name: &str| avail.iter().copied().find(|r| r.name == name);
    let (g, p, oidn) = (by_name("g"), by_name("p"), by_name("oidn"));
    let mut bases: Vec<(&str, Vec<&Row>)> = Vec::new();
    if let (Some(g), Some(p)) = (g, p) {
        bases.push(("min(g, p)", vec![g, p]));
    }
    if let Some(o) = oidn {
        bases.push(("OIDN", vec![o]));
    }
    if bases.is_empty() {
        writeln!(w, "No ratios: neither g and p nor OIDN are among the methods measured.\n")?;
    }
    for (what, base) in &bases {
        for metric in [Metric::RelMse, Metric::Ssim] {
            writeln!(
                w,
                "Mean {0} over the scenes ÷ that of {what}{1}{2} (below 1: better than {what}):\n",
                metric.name(),
                if base.len() > 1 { " (the lower of the two means)" } else { "" },
                if n > 1 { ", at each seed, then the mean ± standard error [min–max] of that ratio over the seeds" } else { "" }
            )?;
            header(w, "method")?;
            let den: Vec<Vec<Option<f64>>> = spps
                .iter()
                .map(|&spp| {
                    let each: Vec<Vec<Option<f64>>> = base.iter().map(|b| v.complete_seed_means(spp, b, metric)).collect();
                    (0..n)
                        .map(|k| {
                            each.iter().map(|e| e[k]).collect::<Option<Vec<f64>>>().map(|x| x.into_iter().fold(f64::INFINITY, f64::min))
                        })
                        .collect()
                })
                .collect();
            for r in &avail {
                write!(w, "| {} |", r.label)?;
                for (j, &spp) in spps.iter().enumerate() {
                    let num = v.complete_seed_means(spp, r, metric);
                    let ratios: Vec<f64> = (0..n).filter_map(|k| Some(num[k]? / den[j][k]?)).filter(|x| x.is_finite()).collect();
                    write!(w, " {} |", cell(&ratios, 3))?;
                }
                writeln!(w)?;
            }
            writeln!(w)?;
        }
    }
    weights(w, v, &avail, &spps)
}

/// The mean weight per expert of every row whose records carry it: a blending method's W, or a
/// bound's share of pixels per expert; mean over scenes and seeds per spp, then per scene.
fn weights(w: &mut String, v: &View, avail: &[&Row], spps: &[u32]) -> std::fmt::Result {
    let (a, o) = (v.a, v.o);
    let mut any = false;
    for r in avail {
        // (scene index, spp) → the records' weight lists over the seeds.
        let mut keys: Vec<String> = Vec::new();
        let mut cells: Vec<(usize, u32, Vec<&Weights>)> = Vec::new();
        for (si, s) in o.scenes.iter().enumerate() {
            for &spp in spps {
                let ws: Vec<&Weights> = a.seeds.iter().filter_map(|&seed| v.rec(s, spp, r, seed).and_then(|x| x.mean_w.as_ref())).collect();
                for list in &ws {
                    for (k, _) in list.iter() {
                        if !keys.contains(k) {
                            keys.push(k.clone());
                        }
                    }
                }
                if !ws.is_empty() {
                    cells.push((si, spp, ws));
                }
            }
        }
        if cells.is_empty() {
            continue;
        }
        if !any {
            writeln!(w, "## Mean weight per expert\n")?;
            writeln!(
                w,
                "For a method that blends experts, the mean over the image of each expert's weight (the guided models: W_G and \
                 W_P = 1 − W_G per branch); for a bound, the share of the image's pixels taken from each expert's output. Mean over \
                 the scenes and seeds, then per scene (mean over seeds).\n"
            )?;
            any = true;
        }
        let value = |list: &[&Weights], k: &str| -> Option<f64> {
            mean(&list.iter().filter_map(|l| l.iter().find(|(n, _)| n == k).map(|x| x.1)).collect::<Vec<_>>())
        };
        writeln!(w, "### {}\n", r.label)?;
        writeln!(w, "| spp | {} |\n|---|{}", keys.join(" | "), "---|".repeat(keys.len()))?;
        for &spp in spps {
            let all: Vec<&Weights> = cells.iter().filter(|c| c.1 == spp).flat_map(|c| c.2.iter().copied()).collect();
            if all.is_empty() {
                continue;
            }
            write!(w, "| {spp} |")?;
            for k in &keys {
                write!(w, " {} |", f(value(&all, k), 3))?;
            }
            writeln!(w)?;
        }
        writeln!(w, "\n<details><summary>per scene</summary>\n")?;
        writeln!(w, "| scene | spp | {} |\n|---|---|{}", keys.join(" | "), "---|".repeat(keys.len()))?;
        for (si, spp, list) in &cells {
            write!(w, "| {} | {spp} |", o.scenes[*si].name)?;
            for k in &keys {
                write!(w, " {} |", f(value(list, k), 3))?;
            }
            writeln!(w)?;
        }
        writeln!(w, "\n</details>\n")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three values 1, 2, 6: mean 3, sample sd √7, SEM √7/√3 = 1.527525.
    #[test]
    fn stats_of_three() {
        let (m, sem, lo, hi) = stats(&[2.0, 6.0, 1.0]).unwrap();
        assert_eq!((m, lo, hi), (3.0, 1.0, 6.0));
        assert!((sem - 1.527525).abs() < 1e-6, "{sem}");
        assert_eq!(cell(&[2.0, 6.0, 1.0], 2), "3.00 ± 1.53 [1.00–6.00]");
        assert_eq!(cell(&[0.5], 3), "0.500");
        assert_eq!(cell(&[], 3), "–");
    }
}
