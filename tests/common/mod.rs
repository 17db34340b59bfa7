//! Helpers the end-to-end tests share: running the binary, fresh output folders, a one-scene
//! test list, and reading the results page's tables.
// Each test binary compiles its own copy and uses only some of these.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository root (the binary's working directory in every test).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `pixguide ARGS`, run from the repository root.
pub fn pixguide(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pixguide")).args(args).current_dir(root()).output().unwrap()
}

/// An empty folder under the test target's temporary folder (emptied if a previous run left it).
pub fn out_dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The standard output of a run that must have succeeded.
pub fn ok(out: &Output, what: &str) -> String {
    assert!(out.status.success(), "{what} failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The standard error of a run that must have failed.
pub fn failed(out: &Output, what: &str) -> String {
    assert!(!out.status.success(), "{what} should have failed");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A scene list in `dir` naming the shipped cornell-box scene (absolute path), with its
/// committed reference copied to `dir/references/` (where eval looks for references) if
/// `with_reference`.
pub fn scene_list(dir: &Path, with_reference: bool) -> PathBuf {
    std::fs::create_dir_all(dir.join("references")).unwrap();
    if with_reference {
        for ext in ["exr", "json"] {
            std::fs::copy(root().join(format!("scenes/references/cornell-box.{ext}")), dir.join(format!("references/cornell-box.{ext}")))
                .unwrap();
        }
    }
    let list = dir.join("list.txt");
    std::fs::write(&list, format!("# test list\n{}\n", root().join("scenes/cornell-box/scene.toml").display())).unwrap();
    list
}

/// The cells after the label of the first markdown row starting with `| label |` after `heading`.
pub fn row<'a>(md: &'a str, heading: &str, label: &str) -> Vec<&'a str> {
    let section = &md[md.find(heading).unwrap_or_else(|| panic!("no `{heading}` in\n{md}"))..];
    let line = section.lines().find(|l| l.starts_with(&format!("| {label} |"))).unwrap_or_else(|| panic!("no row {label} after {heading}"));
    line.trim_matches('|').split('|').map(str::trim).skip(1).collect()
}
