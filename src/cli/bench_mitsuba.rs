//! `pixguide bench`'s integrator section: our paths/s against Mitsuba 3's on the same scene and
//! settings, run by run alternating in one process. Mitsuba runs in a Python child
//! (tools/mitsuba/bench.py) that stays alive between runs, so its one-time JIT compilation is
//! done once, untimed, before the first timed run.

use anyhow::{anyhow, bail, Context, Result};
use renderer::film::BufferRequest;
use renderer::integrator::{self, RenderOptions};
use renderer::scene::{export_mitsuba, Scene};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::thread::JoinHandle;
use tools_venv::{libllvm_for_drjit, mitsuba_python};

/// What both renderers are asked to do.
pub struct Settings {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub max_bounces: u32,
    pub repeat: u32,
    pub threads: usize,
}

/// Parses `WxH` (`--integrator-size`).
pub fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let bad = || format!("expected WIDTHxHEIGHT with both in 1..=16384 (e.g. 128x128), got {s:?}");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let parse = |v: &str| v.trim().parse::<u32>().ok().filter(|&v| (1..=16384).contains(&v));
    Ok((parse(w).ok_or_else(bad)?, parse(h).ok_or_else(bad)?))
}

/// The Mitsuba side: how it was set up, and its best run.
struct MitsubaSide {
    session: Session,
    /// Why `scalar_rgb` was used instead of `llvm_ad_rgb`, if it was.
    fallback: Option<String>,
    libllvm: Option<PathBuf>,
}

/// One timed Mitsuba render.
struct MitsubaRun {
    seconds: f64,
    /// CPU time of the whole Mitsuba process during the render (all threads).
    cpu_seconds: f64,
    /// Kernels Dr.Jit compiled during this run instead of taking them from its cache.
    compiled_kernels: u64,
    mean: [f64; 3],
}

/// What the child reported after its untimed warm-up render.
struct Ready {
    variant: String,
    version: String,
    threads: u64,
    warmup_seconds: f64,
    fallback_reason: Option<String>,
}

/// A running tools/mitsuba/bench.py.
struct Session {
    child: Child,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
    stderr: Option<JoinHandle<String>>,
    ready: Ready,
}

impl Session {
    /// Starts the child and waits for its warm-up render; an error carries the child's last line
    /// of error output (an LLVM abort, a Python exception).
    fn start(python: &Path, script: &Path, xml: &Path, s: &Settings, variant: &str, libllvm: Option<&Path>) -> Result<Session> {
        let mut cmd = Command::new(python);
        cmd.arg(script).arg(xml);
        cmd.args([s.width, s.height, s.spp, s.max_bounces + 1].map(|v| v.to_string()));
        cmd.arg(s.threads.to_string()).arg(variant);
        if let Some(p) = libllvm {
            cmd.env("DRJIT_LIBLLVM_PATH", p);
        }
        let mut child = cmd
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("starting {}", script.display()))?;
        let stdin = child.stdin.take().ok_or_else(|| anyhow!("no stdin pipe"))?;
        let stdout = BufReader::new(child.stdout.take().ok_or_else(|| anyhow!("no stdout pipe"))?);
        let mut err = child.stderr.take().ok_or_else(|| anyhow!("no stderr pipe"))?;
        // Drained on its own thread: Mitsuba's warnings could otherwise fill the pipe and stall
        // the child while we wait on stdout.
        let stderr = std::thread::spawn(move || {
            let mut buf = String::new();
            let _ = std::io::Read::read_to_string(&mut err, &mut buf);
            buf
        });
        let mut session = Session {
            child,
            stdin,
            stdout,
            stderr: Some(stderr),
            ready: Ready { variant: String::new(), version: String::new(), threads: 0, warmup_seconds: 0.0, fallback_reason: None },
        };
        let v = session.next_message()?;
        session.ready = Ready {
            variant: v["variant"].as_str().unwrap_or_default().to_string(),
            version: v["version"].as_str().unwrap_or_default().to_string(),
            threads: v["threads"].as_u64().unwrap_or(0),
            warmup_seconds: v["warmup_seconds"].as_f64().unwrap_or(f64::NAN),
            fallback_reason: v["fallback_reason"].as_str().map(str::to_string),
        };
        Ok(session)
    }

    /// The next JSON line from the child, skipping anything else Mitsuba may print on stdout.
    fn next_message(&mut self) -> Result<serde_json::Value> {
        let mut line = String::new();
        loop {
            line.clear();
            if self.stdout.read_line(&mut line)? == 0 {
                let _ = self.child.wait();
                let err = self.stderr.take().and_then(|h| h.join().ok()).unwrap_or_default();
                let last = err.lines().map(str::trim).rfind(|l| !l.is_empty()).unwrap_or("no error output");
                // LLVM's "Cannot select" dumps its DAG after the first line, which names the problem.
                let first_llvm = err.lines().find(|l| l.starts_with("LLVM ERROR"));
                bail!("Mitsuba's bench.py ended early: {}", first_llvm.unwrap_or(last));
            }
            if line.trim_start().starts_with('{') {
                if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line) {
                    return Ok(v);
                }
            }
        }
    }

    fn render(&mut self, seed: u32) -> Result<MitsubaRun> {
        writeln!(self.stdin, "render {seed}")?;
        self.stdin.flush()?;
        let v = self.next_message()?;
        let mean = v["mean"].as_array().map(|a| a.iter().map(|x| x.as_f64().unwrap_or(f64::NAN)).collect::<Vec<_>>()).unwrap_or_default();
        let seconds = v["seconds"].as_f64().ok_or_else(|| anyhow!("Mitsuba's bench.py: no `seconds` in {v}"))?;
        let cpu_seconds = v["cpu_seconds"].as_f64().unwrap_or(f64::NAN);
        Ok(MitsubaRun {
            seconds,
            cpu_seconds,
            compiled_kernels: v["compiled_kernels"].as_u64().unwrap_or(0),
            mean: [0, 1, 2].map(|c| mean.get(c).copied().unwrap_or(f64::NAN)),
        })
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        let _ = writeln!(self.stdin, "quit");
        let _ = self.stdin.flush();
        let _ = self.child.wait();
    }
}

/// CPU time (user + system, all threads) this process has used, in seconds; `None` where
/// /proc is unavailable. On a machine shared with other work, a render's CPU time counts only
/// the time its threads actually ran, which wall time does not.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name, which may itself contain spaces.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the line, 11 and 12 after the name; /proc reports
    // them in USER_HZ, which Linux fixes at 100 for user space.
    let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
    Some(ticks as f64 / 100.0)
}

/// The Mitsuba XML for `scene_path`: the file itself if it is Mitsuba XML, else the scene as we
/// loaded it (at the benchmark's size) exported under `work`.
fn mitsuba_xml(scene_path: &Path, scene: &Scene, work: &Path) -> Result<PathBuf> {
    if scene_path.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml")) {
        return Ok(scene_path.to_path_buf());
    }
    let stem = scene_path.parent().and_then(|p| p.file_name()).unwrap_or_default().to_string_lossy().into_owned();
    Ok(export_mitsuba(scene, &work.join(if stem.is_empty() { "scene".into() } else { stem }))?)
}

/// Sets up Mitsuba (venv, scene, variant). `None` (and one line on stderr saying why) when the
/// comparison cannot run, so the rest of the benchmark still does.
fn setup_mitsuba(scene_path: &Path, scene: &Scene, s: &Settings) -> Option<MitsubaSide> {
    let skip = |e: anyhow::Error| {
        eprintln!("warning: Mitsuba comparison skipped: {e:#}");
        None
    };
    let ws = Path::new(".");
    let venv = match mitsuba_python(&ws.join("target/mitsuba-venv")) {
        Ok(v) => v,
        Err(e) => return skip(e.into()),
    };
    let xml = match mitsuba_xml(scene_path, scene, &ws.join("target/mitsuba-bench")) {
        Ok(x) => x,
        Err(e) => return skip(e),
    };
    let script = ws.join("tools/mitsuba/bench.py");
    let libllvm = libllvm_for_drjit();
    let fallback = match &libllvm {
        Some(lib) => match Session::start(&venv.python, &script, &xml, s, "llvm_ad_rgb", Some(lib.as_path())) {
            Ok(session) => {
                let fallback = session.ready.fallback_reason.clone();
                return Some(MitsubaSide { session, fallback, libllvm: libllvm.clone() });
            }
            // Dr.Jit 1.5 needs a recent LLVM for the kernels it emits (LLVM 15 aborts here).
            Err(e) => format!(
                "llvm_ad_rgb failed with {} ({e:#}); a newer libLLVM fixes it, e.g. Debian's `apt-get install libllvm19`",
                lib.display()
            ),
        },
        None => "no libLLVM found (install one, e.g. Debian's `apt-get install libllvm19`, or set DRJIT_LIBLLVM_PATH)".into(),
    };
    match Session::start(&venv.python, &script, &xml, s, "scalar_rgb", None) {
        Ok(session) => Some(MitsubaSide { session, fallback: Some(fallback), libllvm }),
        Err(e) => skip(e),
    }
}

/// What `integrator_vs_mitsuba` measured: our best paths/s and, when Mitsuba ran, ours/Mitsuba
/// best against best and the median of the run-by-run pairs.
pub struct VsMitsuba {
    pub ours_paths_per_sec: f64,
    pub best_ratio: Option<f64>,
    pub median_ratio: Option<f64>,
}

/// Our paths/s and Mitsuba's on `scene_path` with the settings of `s`, alternating run by run
/// (best of `s.repeat` each), with the ratio; Mitsuba is left out when `mitsuba` is false or it
/// cannot be set up.
pub fn integrator_vs_mitsuba(scene_path: &Path, s: &Settings, mitsuba: bool) -> Result<VsMitsuba> {
    if s.spp == 0 {
        bail!("--integrator-spp must be at least 1");
    }
    let mut scene = Scene::load(scene_path)?;
    // A new size keeps the field of view along the scene's fov axis, as Mitsuba's film does.
    scene.camera.width = s.width;
    scene.camera.height = s.height;
    let paths = s.width as f64 * s.height as f64 * s.spp as f64;
    println!(
        "\nintegrator: {} at {}x{}, {} spp, {} bounces (Mitsuba max_depth {}), no Russian roulette, box filter, independent sampler; {} threads; best of {}, ours and Mitsuba alternating (who goes first alternates too)",
        scene_path.display(),
        s.width,
        s.height,
        s.spp,
        s.max_bounces,
        s.max_bounces + 1,
        s.threads,
        s.repeat
    );
    let mut side = if mitsuba { setup_mitsuba(scene_path, &scene, s) } else { None };
    if let Some(m) = &side {
        let r = &m.session.ready;
        let llvm = match (&m.libllvm, r.variant.starts_with("llvm")) {
            (Some(p), true) => format!(", libLLVM {}", p.display()),
            _ => String::new(),
        };
        println!("  Mitsuba {} variant {}{llvm}, {} threads", r.version, r.variant, r.threads);
        if let Some(why) = m.fallback.as_ref().or(r.fallback_reason.as_ref()) {
            println!("  (scalar_rgb because {why})");
        }
        if r.variant.starts_with("llvm") {
            println!("  Mitsuba's JIT warm-up excluded: one untimed render first ({:.2} s: tracing, compiling or loading from Dr.Jit's kernel cache), then the timed ones", r.warmup_seconds);
        } else {
            println!(
                "  one untimed warm-up render first ({:.2} s; scalar_rgb compiles nothing at run time), then the timed ones",
                r.warmup_seconds
            );
        }
    }
    let mut ours_best: Option<(f64, u64)> = None;
    let mut ours_cpu = f64::INFINITY;
    let mut theirs_cpu = f64::INFINITY;
    let mut ours_mean = [0.0f64; 3];
    let mut theirs_best: Option<MitsubaRun> = None;
    let mut compiled = 0u64;
    // ours/Mitsuba speed of each run's pair: the two renders of a pair run back to back, so a
    // change in the host's speed between runs (±15 % here) moves both alike.
    let mut pair_ratios: Vec<f64> = Vec::new();
    for run in 0..s.repeat.max(1) {
        let opts = RenderOptions {
            spp: s.spp,
            seed: run as u64,
            max_bounces: s.max_bounces,
            russian_roulette: false,
            request: BufferRequest::RADIANCE_ONLY,
            crop: None,
            first_sample: 0,
        };
        // Which renders first alternates from run to run, so neither side always follows the
        // other's heat and cache state.
        let (mut ours_secs, mut theirs_secs) = (None, None);
        for ours_turn in if run % 2 == 0 { [true, false] } else { [false, true] } {
            if ours_turn {
                let cpu0 = process_cpu_seconds();
                let (frame, st) = integrator::render(&scene, &opts, &|_| {})?;
                if let (Some(a), Some(b)) = (cpu0, process_cpu_seconds()) {
                    ours_cpu = ours_cpu.min(b - a);
                }
                let secs = st.wall.as_secs_f64();
                ours_secs = Some(secs);
                if ours_best.is_none_or(|(b, _)| secs < b) {
                    ours_best = Some((secs, st.rays));
                    let n = (frame.width * frame.height) as f64;
                    ours_mean = [0, 1, 2].map(|c| frame.radiance.mean.iter().skip(c).step_by(3).map(|&v| v as f64).sum::<f64>() / n);
                }
            } else if let Some(m) = side.as_mut() {
                match m.session.render(run + 1) {
                    Ok(r) => {
                        compiled += r.compiled_kernels;
                        if r.cpu_seconds.is_finite() {
                            theirs_cpu = theirs_cpu.min(r.cpu_seconds);
                        }
                        theirs_secs = Some(r.seconds);
                        if theirs_best.as_ref().is_none_or(|b| r.seconds < b.seconds) {
                            theirs_best = Some(r);
                        }
                    }
                    Err(e) => {
                        eprintln!("warning: Mitsuba comparison stopped: {e:#}");
                        side = None;
                        theirs_best = None;
                    }
                }
            }
        }
        if let (Some(o), Some(t)) = (ours_secs, theirs_secs) {
            pair_ratios.push(t / o);
        }
    }
    let (secs, rays) = ours_best.ok_or_else(|| anyhow!("no run"))?;
    let ours = paths / secs;
    let mut result = VsMitsuba { ours_paths_per_sec: ours, best_ratio: None, median_ratio: None };
    println!("  ours     {:>7.3} M paths/s ({:.2} s per render, {:.3} M rays/s)", ours * 1e-6, secs, rays as f64 / secs * 1e-6);
    if let (Some(m), Some(t)) = (&side, &theirs_best) {
        let theirs = paths / t.seconds;
        let jit = if m.session.ready.variant.starts_with("llvm") {
            format!("; {compiled} kernels compiled during the timed runs")
        } else {
            String::new()
        };
        println!("  Mitsuba  {:>7.3} M paths/s ({:.2} s per render{jit})", theirs * 1e-6, t.seconds);
        println!("  ours/Mitsuba {:.2}x ({}, wall clock, best against best)", ours / theirs, m.session.ready.variant);
        result.best_ratio = Some(ours / theirs);
        result.median_ratio = renderer::bench::median(&pair_ratios);
        if let Some(median) = renderer::bench::median(&pair_ratios) {
            let list: Vec<String> = pair_ratios.iter().map(|r| format!("{r:.2}")).collect();
            println!("  ours/Mitsuba run by run (the two renders of a run back to back): {} ; median {median:.2}x", list.join(" "));
        }
        if ours_cpu.is_finite() && theirs_cpu.is_finite() && ours_cpu > 0.0 && theirs_cpu > 0.0 {
            println!(
                "  per CPU second (all threads of each process, best run): ours {:.3} M paths, Mitsuba {:.3} M paths; ours/Mitsuba {:.2}x",
                paths / ours_cpu * 1e-6,
                paths / theirs_cpu * 1e-6,
                theirs_cpu / ours_cpu
            );
        }
        let rel = |a: f64, b: f64| 100.0 * (a - b) / b;
        println!(
            "  image mean RGB: ours {:.4} {:.4} {:.4}, Mitsuba {:.4} {:.4} {:.4} ({:+.2}% {:+.2}% {:+.2}%)",
            ours_mean[0],
            ours_mean[1],
            ours_mean[2],
            t.mean[0],
            t.mean[1],
            t.mean[2],
            rel(ours_mean[0], t.mean[0]),
            rel(ours_mean[1], t.mean[1]),
            rel(ours_mean[2], t.mean[2])
        );
    }
    Ok(result)
}
