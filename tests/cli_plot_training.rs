//! `pixguide plot-training` on synthetic training logs: the PNG holds every run's curve in both
//! panels, the Markdown table has the best validation and flatten point the data implies, and bad
//! logs give errors naming the file (and line).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn pixguide(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pixguide")).args(args).current_dir(env!("CARGO_MANIFEST_DIR")).output().unwrap()
}

fn write(dir: &Path, name: &str, lines: &[String]) -> String {
    let p = dir.join(name);
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    p.to_str().unwrap().to_string()
}

fn val(stage: u32, step: u32, total: u32, rel_mse: f64, seconds: Option<f64>) -> String {
    let s = seconds.map(|s| format!(",\"seconds\":{s:.2}")).unwrap_or_default();
    format!("{{\"event\":\"val\",\"stage\":{stage},\"step\":{step},\"total_step\":{total},\"rel_mse\":{rel_mse},\"best\":true{s}}}")
}

fn step(stage: u32, step: u32, seconds: f64) -> String {
    format!("{{\"event\":\"step\",\"stage\":{stage},\"step\":{step},\"loss\":0.1,\"seconds\":{seconds}}}")
}

/// Three runs: `a` has validation times and flattens at step 30 (0.030, after which the best is
/// 0.029: 3.3 % lower); `b` is an old log (time from its 6-s steps, 10 + 5 steps over two
/// stages) still falling at its end; `c` was resumed (a second stage event) and flattens at 200.
fn logs(dir: &Path) -> Vec<String> {
    let mut a = vec!["{\"event\":\"stage\",\"stage\":0,\"kind\":\"branches\",\"steps\":50,\"from_step\":0}".to_string()];
    for (k, r) in [0.1, 0.05, 0.03, 0.029, 0.0295].into_iter().enumerate() {
        let k = k as u32 + 1;
        a.extend((k * 10 - 9..=k * 10).map(|s| step(0, s, 1.0)));
        a.push(val(0, k * 10, k * 10, r, Some(60.0 * k as f64)));
    }
    let mut b = vec!["{\"event\":\"stage\",\"stage\":0,\"kind\":\"branches\",\"steps\":10,\"from_step\":0}".to_string()];
    b.extend((1..=5).map(|s| step(0, s, 6.0)));
    b.push(val(0, 5, 5, 0.2, None));
    b.extend((6..=10).map(|s| step(0, s, 6.0)));
    b.push(val(0, 10, 10, 0.1, None));
    b.push("{\"event\":\"stage_end\",\"stage\":0,\"steps\":10,\"reason\":\"steps done\"}".into());
    b.push("{\"event\":\"checkpoint\",\"dir\":\"x.ckpt\"}".into());
    b.push("{\"event\":\"something_new\",\"x\":[1,2]}".into());
    b.extend((1..=5).map(|s| step(1, s, 6.0)));
    b.push(val(1, 5, 15, 0.05, None));
    let stage = |from: u32| format!("{{\"event\":\"stage\",\"stage\":0,\"kind\":\"joint\",\"steps\":400,\"from_step\":{from}}}");
    let c = vec![
        stage(0),
        val(0, 100, 100, 0.08, Some(30.0)),
        val(0, 200, 200, 0.06, Some(60.0)),
        stage(200),
        val(0, 300, 300, 0.059, Some(100.0)),
        val(0, 400, 400, 0.058, Some(130.0)),
    ];
    vec![
        write(dir, "run-a.safetensors.log.jsonl", &a),
        write(dir, "run-b.safetensors.log.jsonl", &b),
        write(dir, "run-c.safetensors.log.jsonl", &c),
    ]
}

/// The table row of `run` as its cells.
fn row(table: &str, run: &str) -> Vec<String> {
    let line = table.lines().find(|l| l.starts_with(&format!("| {run} "))).unwrap_or_else(|| panic!("no row {run} in\n{table}"));
    line.trim_matches('|').split('|').map(|c| c.trim().to_string()).collect()
}

#[test]
fn plots_and_tabulates_synthetic_runs() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("plot_training");
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let logs = logs(&dir);
    let png = dir.join("out/curves.png");
    let mut args = vec!["plot-training"];
    args.extend(logs.iter().map(String::as_str));
    args.extend(["-o", png.to_str().unwrap(), "--title", "synthetic"]);
    let o = pixguide(&args);
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");

    // run | steps | wall min | best relMSE | best step | best min | flattens at step (min)
    assert!(stdout.contains("first val no later val beats by > 5 %"), "{stdout}");
    assert_eq!(row(&stdout, "run-a"), ["run-a", "50", "5.0", "0.02900", "40", "4.0", "30 (3.0)"]);
    assert_eq!(row(&stdout, "run-b *"), ["run-b *", "15", "1.5", "0.05000", "15", "1.5", "not yet"]);
    assert_eq!(row(&stdout, "run-c"), ["run-c", "400", "2.2", "0.05800", "400", "2.2", "200 (1.0)"]);
    assert!(stdout.contains("leave out validation"), "{stdout}");

    let img = image::open(&png).unwrap().to_rgb8();
    // 1100 wide; 34 title + 440 panels + one legend row (30) + two note lines (36) + 6.
    assert_eq!(img.dimensions(), (1100, 546));
    // Each run's colour (Tableau 10: blue, orange, green) is drawn in both panels, above the
    // legend (whose swatches alone would not count).
    for (k, rgb) in [[31u8, 119, 180], [255, 127, 14], [44, 160, 44]].into_iter().enumerate() {
        for (half, xs) in [(0..550u32), (550..1100u32)].into_iter().enumerate() {
            let n = xs.flat_map(|x| (34..474u32).map(move |y| (x, y))).filter(|&(x, y)| img.get_pixel(x, y).0 == rgb).count();
            assert!(n >= 40, "run {k}: {n} pixels of its colour in panel {half}");
        }
    }

    // --labels renames the runs, and must match the number of logs.
    let mut args = vec!["plot-training"];
    args.extend(logs.iter().map(String::as_str));
    args.extend(["-o", png.to_str().unwrap(), "--labels", "alpha,beta,gamma"]);
    let o = pixguide(&args);
    assert!(o.status.success());
    assert_eq!(row(&String::from_utf8_lossy(&o.stdout), "alpha")[6], "30 (3.0)");
    let o = pixguide(&["plot-training", &logs[0], "-o", png.to_str().unwrap(), "--labels", "x,y"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--labels has 2 names for 1 logs"));
}

#[test]
fn bad_logs_are_errors_naming_the_file() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("plot_training_bad");
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("x.png");
    let run = |log: &str| {
        let o = pixguide(&["plot-training", log, "-o", out.to_str().unwrap()]);
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let malformed =
        write(&dir, "malformed.log.jsonl", &[step(0, 1, 1.0), val(0, 1, 1, 0.1, None), "{\"event\":\"val\",\"stage\":0,".into()]);
    let e = run(&malformed);
    assert!(e.contains(&format!("{malformed}, line 3, column 25: not valid JSON")), "{e}");
    let missing = write(&dir, "missing.log.jsonl", &[step(0, 1, 1.0), "{\"event\":\"val\",\"rel_mse\":0.1}".into()]);
    let e = run(&missing);
    assert!(e.contains(&format!("{missing}, line 2")) && e.contains("total_step"), "{e}");
    let empty = write(&dir, "empty.log.jsonl", &[]);
    let e = run(&empty);
    assert!(e.contains(&format!("{empty}: empty log")), "{e}");
    let no_val = write(&dir, "noval.log.jsonl", &[step(0, 1, 1.0), step(0, 2, 1.0)]);
    let e = run(&no_val);
    assert!(e.contains(&format!("{no_val}: no validation events")), "{e}");
    assert!(!out.exists());
}
