//! Our images against Mitsuba 3's, scene by scene, at equal settings: the same scene file (or,
//! for the TOML Cornell box, the scene as we loaded it, exported to Mitsuba XML), camera, image
//! size, path depth, a box filter (every sample lands in its own pixel), independent random
//! samples and no Russian roulette on either side. Three statistical tests per scene, each at a
//! family-wise significance of `ALPHA` (Šidák-corrected for the number of tests in the family),
//! all Welch t-tests on the difference of the two means with the variance of each mean
//! estimated from its own render:
//! - the image mean per channel (3 tests);
//! - 8×8-pixel blocks per channel (catches a bias of a few percent over a region);
//! - every pixel per channel, as Mitsuba's own test suite does it (catches a wrong texture, a
//!   missing highlight, a shifted or mirrored image).
//!
//! Our variance of each pixel mean comes from the samples (the frame's variance buffer);
//! Mitsuba's from `SEEDS` independent renders (tools/mitsuba/render.py explains why not its
//! `moment` integrator), so its estimate has SEEDS − 1 degrees of freedom and each test uses
//! Welch–Satterthwaite's degrees of freedom. docs/mitsuba-crosscheck.md has the results.
//!
//! Needs python3 with venv support and network access to PyPI the first time: Mitsuba 3
//! (`mitsuba`, scalar_rgb variant, and numpy) is installed into `target/mitsuba-venv` and
//! reused. Without it the test fails; like the Embree cross-check it is in the network tier
//! (`#[ignore]`d, so run with `-- --include-ignored`, as CI does: docs/architecture.md, "Tests").
//! Pictures (ours | Mitsuba | z) and the numbers go to target/mitsuba-crosscheck/.

use renderer::film::BufferRequest;
use renderer::integrator::{self, RenderOptions};
use renderer::scene::{export_mitsuba, load_description, MaterialKind, Scene};
use renderer::stats::{sidak, t_threshold, t_two_sided_p};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use tools_venv::{mitsuba_python, MITSUBA};

/// Family-wise significance of each of the three tests of a scene. The renders are
/// deterministic (fixed seeds on both sides), so a pass or a failure is reproducible; ALPHA says
/// how unlikely a failure would be if both renderers computed the same image.
const ALPHA: f64 = 1e-3;
/// Mitsuba renders each scene this many times with different seeds.
const SEEDS: u32 = 16;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("renderer/ has a parent").to_path_buf()
}

/// Per-pixel, per-channel means and variances of the means (RGB, row-major from the top left).
struct Image {
    width: u32,
    height: u32,
    mean: Vec<f64>,
    var: Vec<f64>,
    /// Degrees of freedom of each variance estimate.
    dof: f64,
    seconds: f64,
}

struct Case {
    name: &'static str,
    /// The file we load.
    ours: PathBuf,
    /// Mitsuba XML; `None`: export the scene as we loaded it.
    mitsuba: Option<PathBuf>,
    width: u32,
    height: u32,
    /// Our samples per pixel; Mitsuba renders SEEDS × spp / SEEDS.
    spp: u32,
    /// Mitsuba's max_depth (path segments); our max_bounces is one less.
    max_depth: u32,
    /// Triangles of this material are lifted by 1 mm (+y) on both sides: a face lying in
    /// another surface's plane makes every hit there a tie, which each renderer's BVH breaks
    /// its own way (frosted-plastic's ice cube stands exactly on the floor).
    lift: Option<&'static str>,
}

/// Rough plastic coats of exported scenes are capped at this GGX/Beckmann alpha. Mitsuba's
/// `roughplastic` lets light through its coat by the single-scattering microfacet
/// transmittance T(μ), ours by 1 − E(μ) (E the coat lobe's directional albedo: energy the
/// single-scattering lobe loses goes to the base), so our diffuse lobe is brighter by
/// (1 − E(μi))(1 − E(μo))/(T(μi) T(μo)): measured 9.5 % at α = 0.5 at normal incidence and up to
/// 30 % over a surface lit at grazing angles (sunlit-ruins' plinth). No Mitsuba BSDF has our coat, so the
/// comparison caps α (on both sides, the same scene) rather than widening every bound.
const PLASTIC_ALPHA_CAP: f32 = 0.03;

/// The scene of a case, at the case's size, as both renderers see it.
fn load_case(case: &Case) -> Scene {
    let mut desc = load_description(&case.ours).unwrap_or_else(|e| panic!("{}: {e}", case.name));
    if let Some(name) = case.lift {
        let m = desc.materials.iter().position(|m| m.name == name).unwrap_or_else(|| panic!("{}: no material {name}", case.name)) as u32;
        let mut lifted = vec![false; desc.mesh.positions.len()];
        for (t, _) in desc.mesh.triangles.iter().zip(&desc.mesh.material).filter(|(_, &tm)| tm == m) {
            t.iter().for_each(|&v| lifted[v as usize] = true);
        }
        for (p, _) in desc.mesh.positions.iter_mut().zip(&lifted).filter(|(_, &l)| l) {
            p.y += 1e-3;
        }
    }
    let mut scene = Scene::new(&case.ours, desc).unwrap_or_else(|e| panic!("{}: {e}", case.name));
    // A new size keeps the field of view along the scene's fov axis, as Mitsuba's film does.
    scene.camera.width = case.width;
    scene.camera.height = case.height;
    if case.mitsuba.is_none() {
        for m in &mut scene.materials {
            if let MaterialKind::Plastic { roughness, .. } = &mut m.kind {
                *roughness = roughness.min(PLASTIC_ALPHA_CAP);
            }
        }
    }
    scene
}

fn render_ours(case: &Case, scene: &Scene) -> Image {
    let opts = RenderOptions {
        spp: case.spp,
        seed: 1,
        max_bounces: case.max_depth - 1,
        russian_roulette: false,
        request: BufferRequest::default(),
        crop: None,
        first_sample: 0,
    };
    let (frame, stats) = integrator::render(scene, &opts, &|_| {}).unwrap_or_else(|e| panic!("{}: {e}", case.name));
    assert_eq!(frame.nonfinite_samples, 0, "{}: non-finite samples", case.name);
    Image {
        width: frame.width,
        height: frame.height,
        mean: frame.radiance.mean.iter().map(|&v| v as f64).collect(),
        var: frame.radiance.var.iter().map(|&v| v as f64).collect(),
        dof: (case.spp - 1) as f64,
        seconds: stats.wall.as_secs_f64(),
    }
}

fn render_mitsuba(python: &Path, xml: &Path, case: &Case, out_dir: &Path) -> Image {
    let out = out_dir.join(format!("{}-mitsuba.bin", case.name));
    let exr = out_dir.join(format!("{}-mitsuba.exr", case.name));
    let script = workspace().join("tools/mitsuba/render.py");
    let spp = case.spp / SEEDS;
    let args = [case.width, case.height, spp, SEEDS, case.max_depth].map(|v| v.to_string());
    let o = Command::new(python)
        .arg(&script)
        .arg(xml)
        .arg(&out)
        .args(&args)
        .arg(&exr)
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", script.display()));
    assert!(o.status.success(), "{}: Mitsuba failed on {}:\n{}", case.name, xml.display(), String::from_utf8_lossy(&o.stderr));
    let data = std::fs::read(&out).unwrap();
    assert_eq!(&data[..8], b"PGMI0001");
    let u = |o: usize| u32::from_le_bytes(data[o..o + 4].try_into().unwrap());
    let (w, h) = (u(8), u(12));
    assert_eq!((w, h, u(16), u(20)), (case.width, case.height, SEEDS, spp));
    let seconds = f64::from_le_bytes(data[24..32].try_into().unwrap());
    let n = (w * h * 3) as usize;
    assert_eq!(data.len(), 32 + 8 * n);
    let f = |i: usize| f32::from_le_bytes(data[32 + 4 * i..36 + 4 * i].try_into().unwrap()) as f64;
    Image { width: w, height: h, mean: (0..n).map(f).collect(), var: (0..n).map(|i| f(n + i)).collect(), dof: (SEEDS - 1) as f64, seconds }
}

/// Writes an image in render.py's format (for looking at the differences afterwards).
fn write_image(img: &Image, path: &Path, spp: u32, seeds: u32) {
    let mut b = b"PGMI0001".to_vec();
    for v in [img.width, img.height, seeds, spp] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.extend_from_slice(&img.seconds.to_le_bytes());
    for v in img.mean.iter().chain(&img.var) {
        b.extend_from_slice(&(*v as f32).to_le_bytes());
    }
    std::fs::write(path, b).unwrap();
}

// ---- Statistics -------------------------------------------------------------------------

/// One Welch test: the two means of a cell (a pixel, a block, the image) and their variances.
#[derive(Clone, Copy, Debug)]
struct Welch {
    diff: f64,
    t: f64,
    dof: f64,
    p: f64,
    ours: f64,
    theirs: f64,
}

/// Welch's test on aggregated cells: `cells` lists for each cell the indices (into the images'
/// per-pixel-channel arrays) it averages.
fn welch(a: &Image, b: &Image, idx: &[usize]) -> Welch {
    let k = idx.len() as f64;
    let (mut ma, mut mb, mut va, mut vb) = (0.0, 0.0, 0.0, 0.0);
    for &i in idx {
        ma += a.mean[i];
        mb += b.mean[i];
        va += a.var[i];
        vb += b.var[i];
    }
    let (ma, mb, va, vb) = (ma / k, mb / k, va / (k * k), vb / (k * k));
    // A floor for cells with no variance at all on either side (a constant background seen
    // directly): rounding-level differences (f32, 1e-5 relative) are not disagreements.
    let floor = (1e-5 * ma.abs().max(mb.abs())).powi(2) + 1e-20;
    let v = va + vb + floor;
    // Welch–Satterthwaite, with each side's per-pixel degrees of freedom (sums of independent
    // per-pixel variance estimates have at least as many).
    let dof = (v * v / (va * va / a.dof + vb * vb / b.dof + floor * floor / 1e6)).max(a.dof.min(b.dof));
    let t = (ma - mb) / v.sqrt();
    Welch { diff: ma - mb, t, dof, p: t_two_sided_p(t, dof), ours: ma, theirs: mb }
}

struct Family {
    worst: Welch,
    /// The worst cell's position (pixel or block x, y, channel); channel only for the means.
    at: (u32, u32, usize),
    tests: usize,
    threshold_p: f64,
    failing: usize,
    /// |t| of every test, for the picture (pixel family) and the quantiles.
    t: Vec<f64>,
}

fn family(a: &Image, b: &Image, block: u32) -> Family {
    let (w, h) = (a.width, a.height);
    let (bw, bh) = (w.div_ceil(block), h.div_ceil(block));
    let tests = (bw * bh * 3) as usize;
    let threshold_p = sidak(ALPHA, tests);
    let mut worst: Option<(Welch, (u32, u32, usize))> = None;
    let mut failing = 0;
    let mut ts = Vec::with_capacity(tests);
    for by in 0..bh {
        for bx in 0..bw {
            for c in 0..3 {
                let mut idx = Vec::new();
                for y in by * block..((by + 1) * block).min(h) {
                    for x in bx * block..((bx + 1) * block).min(w) {
                        idx.push(((y * w + x) * 3) as usize + c);
                    }
                }
                let r = welch(a, b, &idx);
                failing += (r.p < threshold_p) as usize;
                ts.push(r.t.abs());
                if worst.as_ref().is_none_or(|(wr, _)| r.p < wr.p) {
                    worst = Some((r, (bx, by, c)));
                }
            }
        }
    }
    let (worst, at) = worst.expect("non-empty image");
    Family { worst, at, tests, threshold_p, failing, t: ts }
}

fn check_case(python: &Path, case: &Case, out_dir: &Path) -> (String, Vec<String>) {
    let scene = load_case(case);
    let xml = match &case.mitsuba {
        Some(p) => p.clone(),
        None => export_mitsuba(&scene, &out_dir.join(case.name)).unwrap_or_else(|e| panic!("{}: {e}", case.name)),
    };
    let ours = render_ours(case, &scene);
    write_image(&ours, &out_dir.join(format!("{}-ours.bin", case.name)), case.spp, 1);
    let theirs = render_mitsuba(python, &xml, case, out_dir);
    assert_eq!((ours.width, ours.height), (theirs.width, theirs.height));
    let (w, h) = (ours.width, ours.height);

    // Pictures: ours | Mitsuba | per-pixel max |t| over the channels (white = the pixel test's
    // threshold or more).
    let pixels = family(&ours, &theirs, 1);
    let t_px = t_threshold(pixels.threshold_p, (SEEDS - 1) as f64);
    let mut strip = vec![0u8; (3 * w * h * 3) as usize];
    let a = renderer::film::png::tonemap_rgb8(&ours.mean.iter().map(|&v| v as f32).collect::<Vec<_>>(), 0.0);
    let b = renderer::film::png::tonemap_rgb8(&theirs.mean.iter().map(|&v| v as f32).collect::<Vec<_>>(), 0.0);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let i = y * w as usize + x;
            let o = (y * 3 * w as usize + x) * 3;
            strip[o..o + 3].copy_from_slice(&a[i * 3..i * 3 + 3]);
            strip[o + 3 * w as usize..o + 3 * w as usize + 3].copy_from_slice(&b[i * 3..i * 3 + 3]);
            let t = (0..3).map(|c| pixels.t[i * 3 + c]).fold(0.0, f64::max);
            let g = ((t / t_px).min(1.0) * 255.0) as u8;
            strip[o + 6 * w as usize..o + 6 * w as usize + 3].copy_from_slice(&[g, g, g]);
        }
    }
    renderer::film::png::write_rgb8(&out_dir.join(format!("{}.png", case.name)), 3 * w, h, strip).unwrap();

    let mut failures = Vec::new();
    let mut report = format!(
        "{:<14} {w}x{h}, {} spp (ours) vs {}x{} spp (Mitsuba), max_depth {}; render {:.1} s ours, {:.1} s Mitsuba\n",
        case.name,
        case.spp,
        SEEDS,
        case.spp / SEEDS,
        case.max_depth,
        ours.seconds,
        theirs.seconds
    );
    // Image means, one test per channel.
    let all: Vec<Welch> = (0..3).map(|c| welch(&ours, &theirs, &(0..(w * h) as usize).map(|i| 3 * i + c).collect::<Vec<_>>())).collect();
    let p_mean = sidak(ALPHA, 3);
    for (c, r) in all.iter().enumerate() {
        let se = (r.diff / r.t).abs();
        writeln!(
            report,
            "  mean {}: ours {:.5}, Mitsuba {:.5}, diff {:+.3}% (±{:.3}% s.e.), t {:+.2} (bound ±{:.2})",
            ["R", "G", "B"][c],
            r.ours,
            r.theirs,
            100.0 * r.diff / r.theirs,
            100.0 * se / r.theirs,
            r.t,
            t_threshold(p_mean, r.dof)
        )
        .unwrap();
        if r.p < p_mean {
            failures.push(format!(
                "{}: image mean of channel {c} differs: ours {:.5}, Mitsuba {:.5}, t = {:.2}",
                case.name, r.ours, r.theirs, r.t
            ));
        }
    }
    for (label, block, f) in [("8x8 blocks", 8u32, family(&ours, &theirs, 8)), ("pixels", 1, pixels)] {
        let mut sorted = f.t.clone();
        sorted.sort_by(f64::total_cmp);
        let q = |p: f64| sorted[((sorted.len() - 1) as f64 * p) as usize];
        writeln!(
            report,
            "  {label:<10}: {} tests, {} fail (p < {:.2e}, |t| ≳ {:.2}); |t| median {:.2}, 99% {:.2}, max {:.2} at ({}, {}) {}: ours {:.4}, Mitsuba {:.4}",
            f.tests,
            f.failing,
            f.threshold_p,
            t_threshold(f.threshold_p, f.worst.dof),
            q(0.5),
            q(0.99),
            f.worst.t.abs(),
            f.at.0 * block,
            f.at.1 * block,
            ["R", "G", "B"][f.at.2],
            f.worst.ours,
            f.worst.theirs
        )
        .unwrap();
        if f.failing > 0 {
            failures.push(format!(
                "{}: {} of {} {label} differ (worst at ({}, {}) channel {}: ours {:.4}, Mitsuba {:.4}, t = {:.2}, p = {:.2e})",
                case.name,
                f.failing,
                f.tests,
                f.at.0 * block,
                f.at.1 * block,
                f.at.2,
                f.worst.ours,
                f.worst.theirs,
                f.worst.t,
                f.worst.p
            ));
        }
    }
    (report, failures)
}

fn cases() -> Vec<Case> {
    let ws = workspace();
    let xml = |name: &str| ws.join(format!("renderer/tests/mitsuba-scenes/{name}.xml"));
    let own = |name: &'static str, width, height, spp| Case {
        name,
        ours: xml(name),
        mitsuba: Some(xml(name)),
        width,
        height,
        spp,
        max_depth: 6,
        lift: None,
    };
    // The test scenes of scenes/test.txt, exported as we load them (veach-ajar is Mitsuba XML).
    let exported = |name: &'static str| Case {
        name,
        ours: ws.join(format!("scenes/{name}/scene.toml")),
        mitsuba: None,
        width: 48,
        height: 48,
        spp: 512,
        max_depth: 6,
        lift: (name == "frosted-plastic").then_some("ice"),
    };
    let veach = ws.join("scenes/assets/veach-ajar/scene.xml");
    vec![
        exported("cornell-box"),
        Case { name: "veach-ajar", ours: veach.clone(), mitsuba: Some(veach), width: 64, height: 36, spp: 512, max_depth: 6, lift: None },
        exported("primitives"),
        exported("sunlit-ruins"),
        exported("wire-fence"),
        exported("glass-still-life"),
        exported("frosted-plastic"),
        exported("glossy-room"),
        own("metals", 48, 48, 512),
        own("glass", 48, 48, 512),
        own("plastics", 48, 48, 512),
    ]
}

#[test]
#[ignore = "network tier: installs Mitsuba 3 from PyPI the first time; run with --include-ignored"]
fn matches_mitsuba_pixel_by_pixel() {
    let venv = workspace().join("target/mitsuba-venv");
    let v = mitsuba_python(&venv)
        .unwrap_or_else(|e| panic!("the Mitsuba cross-check needs python3 -m venv and `pip install {MITSUBA} numpy` (PyPI) to work: {e}"));
    println!("Mitsuba {} (scalar_rgb), family-wise alpha {ALPHA} per test and scene", v.probe);
    let out_dir = workspace().join("target/mitsuba-crosscheck");
    std::fs::create_dir_all(&out_dir).unwrap();
    let only = std::env::var("PIXGUIDE_MITSUBA_CASES").ok();
    let mut failures = Vec::new();
    let mut all = String::new();
    let mut cases = cases();
    // Ad-hoc scenes for looking into a disagreement: PIXGUIDE_MITSUBA_EXTRA=a.xml,b.xml.
    if let Ok(extra) = std::env::var("PIXGUIDE_MITSUBA_EXTRA") {
        for p in extra.split(',') {
            let name: &'static str = Box::leak(Path::new(p).file_stem().unwrap().to_string_lossy().into_owned().into_boxed_str());
            let depth = std::env::var("PIXGUIDE_MITSUBA_DEPTH").ok().and_then(|d| d.parse().ok()).unwrap_or(6);
            cases.push(Case {
                name,
                ours: p.into(),
                mitsuba: Some(p.into()),
                width: 32,
                height: 32,
                spp: 512,
                max_depth: depth,
                lift: None,
            });
        }
    }
    for case in cases {
        if only.as_deref().is_some_and(|o| !o.split(',').any(|n| n == case.name)) {
            continue;
        }
        let (report, f) = check_case(&v.python, &case, &out_dir);
        failures.extend(f);
        print!("{report}");
        all.push_str(&report);
    }
    std::fs::write(out_dir.join("report.txt"), &all).unwrap();
    assert!(failures.is_empty(), "our renders disagree with Mitsuba's:\n{}", failures.join("\n"));
}
