//! End-to-end: `pixguide train` on a tiny generated dataset trains G and P, then the guided
//! model from them; a stopped-and-resumed run ends with the same weights as a straight one.

use std::path::{Path, PathBuf};
use std::process::Command;

fn pixguide(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_pixguide")).args(args).current_dir(env!("CARGO_MANIFEST_DIR")).output().unwrap();
    assert!(o.status.success(), "{args:?} failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The raw bytes of a safetensors file, its header length and its parsed JSON header.
fn header(path: &Path) -> (Vec<u8>, usize, serde_json::Value) {
    let bytes = std::fs::read(path).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    (bytes, n, header)
}

/// The `__metadata__` of a weight file.
fn metadata(path: &Path) -> serde_json::Value {
    header(path).2["__metadata__"].clone()
}

/// Tensor bytes of a safetensors file (the metadata holds wall times, so files differ).
fn tensors(path: &Path) -> Vec<(String, Vec<u8>)> {
    let (bytes, n, header) = header(path);
    let mut out: Vec<(String, Vec<u8>)> = header
        .as_object()
        .unwrap()
        .iter()
        .filter(|(k, _)| *k != "__metadata__")
        .map(|(k, v)| {
            let o = &v["data_offsets"];
            let (a, b) = (o[0].as_u64().unwrap() as usize, o[1].as_u64().unwrap() as usize);
            (k.clone(), bytes[8 + n + a..8 + n + b].to_vec())
        })
        .collect();
    out.sort();
    out
}

/// A tiny dataset of the shipped Cornell box in `dir`: `shots` training shots of 32² (and the
/// validation shot), 2 and 4 spp, 8-spp references.
fn cornell_dataset(dir: &str, shots: u32) {
    let shots = shots.to_string();
    pixguide(&[
        "dataset",
        "--scenes",
        "scenes/cornell-box/scene.toml",
        "--shots",
        &shots,
        "--spp",
        "2,4",
        "--ref-spp",
        "8",
        "--size",
        "32x32",
        "--quiet",
        "-o",
        dir,
    ]);
}

#[test]
fn train_g_p_guided_and_resume() {
    let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("train");
    std::fs::remove_dir_all(&base).ok();
    let data = base.join("data");
    let d = data.to_str().unwrap();
    cornell_dataset(d, 2);
    let out = |n: &str| base.join(n).to_str().unwrap().to_string();
    let common = [
        "--data",
        d,
        "--patch",
        "24",
        "--batch",
        "2",
        "--branch-steps",
        "2",
        "--finetune-steps",
        "1",
        "--joint-steps",
        "2",
        "--val-every",
        "1",
        "--quiet",
    ];
    let train = |extra: &[&str]| {
        let mut a = vec!["train"];
        a.extend_from_slice(&common);
        a.extend_from_slice(extra);
        pixguide(&a)
    };
    let g = train(&["--method", "g", "-o", &out("g.safetensors")]);
    assert!(g.starts_with("trained g (default): 3 steps"), "{g}");
    train(&["--method", "p", "-o", &out("p.safetensors")]);
    let guided = train(&[
        "--method",
        "guided",
        "--from-g",
        &out("g.safetensors"),
        "--from-p",
        &out("p.safetensors"),
        "-o",
        &out("guided.safetensors"),
    ]);
    assert!(guided.starts_with("trained guided (default): 2 steps"), "{guided}");
    // The guided model holds D_G from G and D_P + PathNet from P, plus E.
    let names: Vec<String> = tensors(&base.join("guided.safetensors")).into_iter().map(|t| t.0).collect();
    for prefix in ["diffuse.d_g.", "diffuse.d_p.", "diffuse.path.", "diffuse.e.", "specular.e."] {
        assert!(names.iter().any(|n| n.starts_with(prefix)), "no {prefix}* tensor");
    }
    // Log: one line per step and per validation, valid JSON with finite numbers.
    let log = std::fs::read_to_string(base.join("g.safetensors.log.jsonl")).unwrap();
    let events: Vec<serde_json::Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(events.iter().filter(|e| e["event"] == "step").count(), 3);
    assert!(events.iter().filter(|e| e["event"] == "val").all(|e| e["rel_mse"].as_f64().is_some_and(f64::is_finite)));
    // A g run can continue from a trained g (warm start: the finetune alone here), and moves it;
    // a P model is refused as its start.
    let g_file = out("g.safetensors");
    let mut w = vec![
        "train",
        "--method",
        "g",
        "--from-g",
        &g_file,
        "--branch-steps",
        "0",
        "--finetune-steps",
        "1",
        "--val-every",
        "1",
        "--quiet",
        "-o",
    ];
    let gw = out("gw.safetensors");
    w.push(&gw);
    w.extend_from_slice(&common[..6]);
    let warm = pixguide(&w);
    assert!(warm.starts_with("trained g (default): 1 steps"), "{warm}");
    let (tw, tg) = (tensors(&base.join("gw.safetensors")), tensors(&base.join("g.safetensors")));
    assert_eq!(tw.iter().map(|t| &t.0).collect::<Vec<_>>(), tg.iter().map(|t| &t.0).collect::<Vec<_>>());
    assert_ne!(tw, tg, "the warm-started finetune step changed nothing");
    let o = Command::new(env!("CARGO_BIN_EXE_pixguide"))
        .args([
            "train",
            "--data",
            d,
            "--method",
            "g",
            "--from-p",
            &out("p.safetensors"),
            "--patch",
            "24",
            "-o",
            &out("x.safetensors"),
            "--quiet",
        ])
        .output()
        .unwrap();
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--from-p"), "{}", String::from_utf8_lossy(&o.stderr));
    // Guided without its pretrained models is a clear error, not a crash.
    let o = Command::new(env!("CARGO_BIN_EXE_pixguide"))
        .args(["train", "--data", d, "--method", "guided", "--patch", "24", "-o", &out("x.safetensors"), "--quiet"])
        .output()
        .unwrap();
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--from-g"));
    // --all trains the whole comparison, reading each kind of dataset once for all ten runs;
    // at --all-scale 0.001 its g run has 3 branch steps and 1 finetune step (the plan's 2900 + 400),
    // and the shared dataset gives it the same weights as a standalone run's own read.
    let all_dir = out("all");
    let mut a = vec!["train", "--all", "--all-scale", "0.001", "--out-dir", &all_dir];
    a.extend_from_slice(&common[..6]);
    a.extend_from_slice(&["--val-every", "1", "--quiet"]);
    let o = Command::new(env!("CARGO_BIN_EXE_pixguide")).args(&a).current_dir(env!("CARGO_MANIFEST_DIR")).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");
    assert!(stdout.contains("plan done"), "{stdout}");
    assert_eq!(stderr.matches(" loaded in ").count(), 2, "{stderr}");
    for name in ["g", "p", "both", "guided", "fix-n-train", "radiance-only", "full-n-full"] {
        assert!(base.join("all").join(format!("{name}-default.safetensors")).exists(), "{name}");
    }
    for name in ["g", "p", "guided"] {
        let f = base.join("all").join(format!("{name}-half.safetensors"));
        assert_eq!(metadata(&f)["pixguide.preset"], "half", "{name}-half");
    }
    let mut g3 = vec!["train", "--method", "g", "--branch-steps", "3", "--finetune-steps", "1", "--val-every", "1", "--quiet", "-o"];
    let g3_out = out("g3.safetensors");
    g3.push(&g3_out);
    g3.extend_from_slice(&common[..6]);
    pixguide(&g3);
    assert_eq!(tensors(&base.join("all/g-default.safetensors")), tensors(&base.join("g3.safetensors")));
    // Stop after 2 steps, resume: same tensors as the straight G run above.
    let stopped = train(&["--method", "g", "-o", &out("g2.safetensors"), "--stop-after", "2"]);
    assert!(stopped.starts_with("paused after 2 steps"), "{stopped}");
    assert!(!base.join("g2.safetensors").exists());
    train(&["--method", "g", "-o", &out("g2.safetensors"), "--resume"]);
    assert_eq!(tensors(&base.join("g2.safetensors")), tensors(&base.join("g.safetensors")));
}

/// `--backend tch` in a build without the `tch` feature fails before reading any data, naming
/// the feature; with the feature, a G model trains on LibTorch.
#[test]
fn backend_tch() {
    let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("train-backend");
    std::fs::remove_dir_all(&base).ok();
    let out = base.join("g.safetensors");
    #[cfg(not(feature = "tch"))]
    {
        let o = Command::new(env!("CARGO_BIN_EXE_pixguide"))
            .args(["train", "--data", "no-such-dataset", "--backend", "tch", "-o", out.to_str().unwrap()])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains("--features tch") && err.contains("install_libtorch.sh"), "{err}");
    }
    #[cfg(feature = "tch")]
    {
        let data = base.join("data");
        let d = data.to_str().unwrap();
        pixguide(&[
            "dataset",
            "--scenes",
            "scenes/cornell-box/scene.toml",
            "--shots",
            "2",
            "--spp",
            "2",
            "--ref-spp",
            "8",
            "--size",
            "32x32",
            "--quiet",
            "-o",
            d,
        ]);
        let g = pixguide(&[
            "train",
            "--backend",
            "tch",
            "--data",
            d,
            "--patch",
            "24",
            "--batch",
            "2",
            "--branch-steps",
            "2",
            "--finetune-steps",
            "0",
            "--val-every",
            "1",
            "--quiet",
            "--method",
            "g",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(g.starts_with("trained g (default): 2 steps"), "{g}");
    }
}

/// `pixguide calibrate` on a one-shot dataset: the shipped both (preset `edge-noise`, an f16 file,
/// which calibrate writes back as it read it) gets the best of the tried exponents written into
/// its config, with the same tensors and a provenance note;
/// a model without guides (a two-step `default` g trained here) and a negative exponent are
/// refused.
#[test]
fn calibrate_writes_the_kept_exponent_and_nothing_else() {
    let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("calibrate");
    std::fs::remove_dir_all(&base).ok();
    let data = base.join("data");
    let d = data.to_str().unwrap();
    cornell_dataset(d, 1);
    let input = "denoiser/weights/both-default.safetensors";
    let out = base.join("g.safetensors");
    let stdout =
        pixguide(&["calibrate", "--data", d, "--weights", input, "--exponents", "0,1", "--patch", "24", "-o", out.to_str().unwrap()]);
    let kept: f64 = stdout
        .strip_prefix("kept γ = ")
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(kept == 0.0 || kept == 1.0, "{stdout}");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    assert_eq!(tensors(&out), tensors(&root.join(input)));
    let meta = metadata(&out);
    let config: serde_json::Value = serde_json::from_str(meta["pixguide.config"].as_str().unwrap()).unwrap();
    assert_eq!(config["mskp"]["guide_gain_exponent"].as_f64(), Some(kept));
    let provenance = meta.to_string();
    assert!(provenance.contains(&format!("guide_gain_exponent 0 -> {kept}")), "{provenance}");
    let plain = base.join("plain-g.safetensors");
    let plain = plain.to_str().unwrap();
    pixguide(&[
        "train",
        "--data",
        d,
        "--method",
        "g",
        "--patch",
        "24",
        "--batch",
        "1",
        "--branch-steps",
        "2",
        "--finetune-steps",
        "0",
        "--quiet",
        "-o",
        plain,
    ]);
    for (weights, exps, why) in
        [(plain, "--exponents=0,1", "no edge-stopping guides"), (input, "--exponents=-1", "finite values in [0, 4]")]
    {
        let o = Command::new(env!("CARGO_BIN_EXE_pixguide"))
            .args([
                "calibrate",
                "--data",
                d,
                "--weights",
                weights,
                exps,
                "--patch",
                "24",
                "-o",
                base.join("x.safetensors").to_str().unwrap(),
            ])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(why), "{weights} {exps}: {err}");
    }
}
