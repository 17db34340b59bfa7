//! End-to-end: `pixguide dataset` writes every file of a shot, resumes without redoing work, and
//! is reproducible from its seed.

use std::path::{Path, PathBuf};
use std::process::Command;

fn dataset(out: &Path, seed: &str) -> String {
    dataset_with(out, seed, &["--shots", "1"])
}

fn dataset_with(out: &Path, seed: &str, extra: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_pixguide"))
        .args([
            "dataset",
            "--scenes",
            "scenes/cornell-box/scene.toml",
            "--spp",
            "1,2",
            "--ref-spp",
            "4",
            "--size",
            "16x16",
            "--quiet",
            "--seed",
            seed,
        ])
        .args(extra)
        .arg("-o")
        .arg(out)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(o.status.success(), "dataset failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn dataset_writes_resumes_and_reproduces() {
    let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("dataset");
    std::fs::remove_dir_all(&base).ok();
    let (a, b) = (base.join("a"), base.join("b"));
    let first = dataset(&a, "5");
    assert!(first.starts_with("2 shots made"), "{first}");
    let shot = a.join("train/cornell-box_000000");
    for f in ["noisy_1spp.exr", "noisy_2spp.exr", "descriptors_2spp.safetensors", "reference.exr", "reference.png", "shot.json"] {
        assert!(shot.join(f).exists(), "{f} missing");
    }
    assert!(a.join("val/cornell-box_100000/shot.json").exists() && a.join("shots.jsonl").exists() && a.join("references.png").exists());
    // A second run finds every shot finished and makes none.
    let again = dataset(&a, "5");
    assert!(again.starts_with("0 shots made (2 already there)"), "{again}");
    // Same seed elsewhere: the same parameters and the same bytes.
    dataset(&b, "5");
    let read = |d: &Path, f: &str| std::fs::read(d.join("train/cornell-box_000000").join(f)).unwrap();
    assert_eq!(read(&a, "shot.json"), read(&b, "shot.json"));
    assert_eq!(read(&a, "noisy_2spp.exr"), read(&b, "noisy_2spp.exr"));
    // Another seed draws another shot (so the equality above can fail).
    let c = base.join("c");
    dataset(&c, "6");
    assert_ne!(read(&a, "shot.json"), read(&c, "shot.json"));
}

/// `--shard K/N` parts are disjoint and cover every shot; copied into one folder, a plain run
/// makes nothing new and writes the same index as a single run, and every file is the same.
#[test]
fn dataset_shards_merge_into_the_single_run() {
    let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("dataset-shards");
    std::fs::remove_dir_all(&base).ok();
    let two = ["--shots", "2"];
    let single = base.join("single");
    let made = dataset_with(&single, "5", &two);
    assert!(made.starts_with("3 shots made"), "{made}");
    let merged = base.join("merged");
    let mut parts_made = 0;
    for k in 1..=2 {
        let part = base.join(format!("part{k}"));
        let out = dataset_with(&part, "5", &[&two[..], &["--shard", &format!("{k}/2")]].concat());
        parts_made += out.split(' ').next().unwrap().parse::<usize>().unwrap();
        for split in ["train", "val"] {
            let Ok(dirs) = std::fs::read_dir(part.join(split)) else { continue };
            for d in dirs.flatten() {
                let to = merged.join(split).join(d.file_name());
                assert!(!to.exists(), "{} made by two parts", to.display());
                std::fs::create_dir_all(&to).unwrap();
                for f in std::fs::read_dir(d.path()).unwrap().flatten() {
                    std::fs::copy(f.path(), to.join(f.file_name())).unwrap();
                }
            }
        }
    }
    assert_eq!(parts_made, 3, "the parts must make every shot once");
    let again = dataset_with(&merged, "5", &two);
    assert!(again.starts_with("0 shots made (3 already there)"), "{again}");
    let read = |d: &Path, f: &str| std::fs::read(d.join(f)).unwrap();
    assert_eq!(read(&single, "shots.jsonl"), read(&merged, "shots.jsonl"));
    for shot in ["train/cornell-box_000000", "train/cornell-box_000001", "val/cornell-box_100000"] {
        for f in ["noisy_2spp.exr", "descriptors_2spp.safetensors", "reference.exr", "shot.json"] {
            assert_eq!(read(&single.join(shot), f), read(&merged.join(shot), f), "{shot}/{f}");
        }
    }
    // A bad part is refused with the flag named.
    let o = Command::new(env!("CARGO_BIN_EXE_pixguide")).args(["dataset", "--shard", "3/2", "-o"]).arg(base.join("bad")).output().unwrap();
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--shard 3/2"));
}
