use super::*;
use crate::ensemble::EnsembleConfig;
use crate::kpcn::KpcnConfig;
use crate::mskp::{EdgeStopping, MsKpConfig};
use crate::pathnet::PathNetConfig;
use crate::preprocess::{prepare, prepare_target};
use checkpoint::flat_values;
use data::Shot;
use film::descriptors::{field, FIELDS};
use film::{Descriptors, Frame, PixelBuffer};
use patches::PatchSampler;
use schedule::ScheduleOptions;
use schedule::{BranchLoss, LossScale};
use stored::StoredImage;

fn tiny() -> DenoiserConfig {
    DenoiserConfig::new(
        KpcnConfig::new(34).with_depth(2).with_width(8).with_conv_kernel(3).with_filter_size(3),
        PathNetConfig::new().with_embed_width(8).with_unet_widths(vec![8, 8]).with_convs_per_block(1).with_out_hidden(8),
        EnsembleConfig::new().with_depth(2).with_width(6).with_conv_kernel(3),
    )
}

const W: usize = 20;
const PATCH: usize = 12;

/// A synthetic shot: a smooth reference with an edge, a noisy render = reference + noise at
/// each spp, random but plausible descriptors.
fn shot(name: &str, seed: u64, spps: &[usize]) -> Shot {
    let mut rng = SplitMix64::new(seed);
    let n = W * W;
    let refc: Vec<f32> = (0..3 * n)
        .map(|k| {
            let i = k / 3;
            let x = i % W;
            0.2 + if x > W / 2 { 0.6 } else { 0.1 } + 0.05 * (k % 3) as f32
        })
        .collect();
    let buf = |ch: usize, mean: Vec<f32>, var: f32| PixelBuffer { channels: ch, var: vec![var; mean.len()], mean };
    let max = *spps.iter().max().unwrap() as u32;
    let mut desc = Descriptors::new(W as u32, W as u32, max);
    for (k, v) in desc.data.iter_mut().enumerate() {
        let f = k % FIELDS;
        *v = if (field::BOUNCE_TYPE..field::ROUGHNESS).contains(&f) { [4.0, 8.0, 17.0][rng.below(3)] } else { rng.next_f64() as f32 };
    }
    let noisy = |rng: &mut SplitMix64, s: usize| {
        let mut noise =
            |v: &[f32], amp: f32| -> Vec<f32> { v.iter().map(|x| (x + amp * (rng.next_f64() as f32 - 0.5) / s as f32).max(0.0)).collect() };
        let diff: Vec<f32> = noise(&refc, 0.4).iter().map(|x| x * 0.7).collect();
        let spec: Vec<f32> = noise(&refc, 0.4).iter().map(|x| x * 0.3).collect();
        let rad: Vec<f32> = diff.iter().zip(&spec).map(|(a, b)| a + b).collect();
        Frame {
            width: W as u32,
            height: W as u32,
            spp: s as u32,
            radiance: buf(3, rad, 0.01),
            diffuse: Some(buf(3, diff, 0.01)),
            specular: Some(buf(3, spec, 0.01)),
            albedo: Some(buf(3, vec![0.6; 3 * n], 0.0)),
            normal: Some(buf(3, (0..3 * n).map(|k| if k % 3 == 2 { 1.0 } else { 0.0 }).collect(), 0.0)),
            depth: Some(buf(1, (0..n).map(|i| 0.1 + 0.01 * (i % W) as f32).collect(), 0.0)),
            depth_scale: 1.0,
            descriptors: Some(desc.clone()),
            nonfinite_samples: 0,
        }
    };
    let mut images = Vec::new();
    for &s in spps {
        images.push(StoredImage::new(&prepare(&noisy(&mut rng, s)).unwrap()));
    }
    // Training reads descriptors from their file, as from a dataset folder. The file is
    // unlinked once open (where the system allows it), so tests leave nothing behind.
    static FILES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = FILES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("pixguide-train-desc-{}-{k}.safetensors", std::process::id()));
    desc.write_safetensors(&path).unwrap();
    let descriptors = Some(film::DescriptorFile::open(&path).unwrap());
    let _ = std::fs::remove_file(&path);
    let mut reference = noisy(&mut rng, 1_000_000);
    reference.radiance.mean = refc.clone();
    reference.diffuse.as_mut().unwrap().mean = refc.iter().map(|x| x * 0.7).collect();
    Shot {
        name: name.into(),
        images,
        descriptors,
        target: prepare_target(&reference).unwrap(),
        sampler: PatchSampler::uniform(W, W, PATCH),
    }
}

fn dataset() -> Dataset {
    let spps = vec![2, 4];
    Dataset {
        root: "synthetic".into(),
        train: (0..3).map(|i| shot(&format!("train/s{i}"), i, &spps)).collect(),
        val: vec![shot("val/v", 99, &spps)],
        spps,
        width: W,
        height: W,
    }
}

fn options(method: Method, ablation: Option<Ablation>, sched: &ScheduleOptions) -> TrainOptions {
    TrainOptions {
        method,
        ablation,
        config: tiny(),
        seed: 5,
        patch: PATCH,
        batch: 2,
        stages: schedule::plan(method, ablation, sched),
        augment: true,
        val_every: 3,
        val_batch: 4,
        patience: None,
        checkpoint_every: 2,
        minutes: None,
        pause_after: None,
        pause_after_minutes: None,
        backend: Default::default(),
        metadata: BTreeMap::new(),
    }
}

fn short() -> ScheduleOptions {
    ScheduleOptions { branch_steps: 4, finetune_steps: 2, joint_steps: 3, scratch_steps: 3, ..Default::default() }
}

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pixguide-train-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn train(data: &Dataset, o: &TrainOptions, dir: Option<&Path>, resume: bool) -> Outcome {
    let m = initial_model(o, None, None, &crate::cpu_training_device()).unwrap();
    run(data, o, m, dir, resume, &mut |_| {}).unwrap()
}

/// The losses of 30 Adam steps at lr 1e-3 on one fixed batch of a fresh tiny `method` model.
fn fit_fixed_batch(method: Method, w_path: f64, loss_scale: LossScale, rel_l2_weight: f64) -> Vec<f32> {
    let data = dataset();
    let o = options(method, None, &short());
    let dev = crate::cpu_training_device();
    let mut model = initial_model(&o, None, None, &dev).unwrap();
    let stage = Stage {
        loss: BranchLoss { loss_scale, rel_l2_weight, rel_l2_inside: false },
        ..Stage::constant(StageKind::Branches, 30, Some(1e-3), None, w_path)
    };
    let (refs, _) = draw_batch(&data, &o, 0, 0);
    let mut optim = optimizer();
    let mut losses = Vec::new();
    for step in 0..30 {
        let (input, target) = batch_tensors(&data.train, &refs, &data.spps, PATCH, o.config.margin(), true, &dev).unwrap();
        let mut rng = SplitMix64::new(step);
        let (m, loss) = train_step(model, &mut optim, input, &target, &stage, 1.0, &[], &mut rng).unwrap();
        model = m;
        losses.push(loss);
    }
    losses
}

/// ~30 Adam steps on one fixed batch (so the loss is a deterministic function of the weights)
/// must lower the per-branch L1 of a tiny P model (PathNet + D_P, L_path on) well below its
/// start. At lr 1e-3 the tiny model can fit one batch much better than its initial (near-box
/// filter) output; 0.8× is far from noise (the loss on a fixed batch has no sampling noise,
/// only the fresh L_path permutations, whose term is ~1 % of the total here) yet lenient
/// enough for any correct gradient path. A broken gradient (wrong sign, no update, detached
/// output) leaves the ratio ≥ 1.
#[test]
fn tiny_model_fits_a_fixed_batch() {
    let losses = fit_fixed_batch(Method::P, 0.1, LossScale::Absolute, 0.0);
    let (first, last) = (losses[0], *losses.last().unwrap());
    assert!(last < 0.8 * first, "loss {first} → {last}: {losses:?}");
}

/// The same fit with each patch's loss relative to its input's error: the loss starts near 1
/// (a near-box filter leaves about the input's error, give or take), falls well below it, and
/// every value is finite (no division by a zero-error patch).
#[test]
fn tiny_model_fits_a_fixed_batch_relative_to_its_input() {
    let losses = fit_fixed_batch(Method::G, 0.0, LossScale::RelativeToInput, 0.0);
    let (first, last) = (losses[0], *losses.last().unwrap());
    assert!(losses.iter().all(|l| l.is_finite()), "{losses:?}");
    assert!((0.1..10.0).contains(&first), "a fresh model's relative loss is {first}, expected about 1");
    assert!(last < 0.8 * first, "loss {first} → {last}: {losses:?}");
}

/// The relative L2 term on top of the relative L1: the same fresh model on the same batch starts
/// higher by exactly the term (positive: a fresh model is not exact), and the mixed loss still
/// falls well below its start. A term that is never added leaves the first losses equal.
#[test]
fn relative_l2_term_adds_to_the_loss_and_still_fits() {
    let plain = fit_fixed_batch(Method::G, 0.0, LossScale::RelativeToInput, 0.0);
    let mixed = fit_fixed_batch(Method::G, 0.0, LossScale::RelativeToInput, 5.0);
    assert!(mixed.iter().all(|l| l.is_finite()), "{mixed:?}");
    assert!(mixed[0] > plain[0] * 1.01, "with the term {} , without {}", mixed[0], plain[0]);
    assert!(*mixed.last().unwrap() < 0.8 * mixed[0], "{mixed:?}");
}

/// Training N steps straight equals N/2, a checkpoint, a fresh process state, and N/2 more —
/// bit for bit, across a stage boundary (branches → finetune) and with validation in between.
#[test]
fn resume_equals_uninterrupted() {
    let data = dataset();
    let o = options(Method::G, None, &short());
    let straight = train(&data, &o, Some(&tmpdir("straight")), false);
    let dir = tmpdir("resume");
    let mut first = o.clone();
    first.pause_after = Some(3);
    let half = train(&data, &first, Some(&dir), false);
    assert!(half.paused);
    let mut again = o.clone();
    again.pause_after = Some(2); // crosses into the finetune stage
    let more = train(&data, &again, Some(&dir), true);
    assert!(more.paused && more.total_steps == 5);
    let rest = train(&data, &o, Some(&dir), true);
    assert!(!rest.paused);
    assert_eq!(rest.total_steps, straight.total_steps);
    assert_eq!(flat_values(&rest.model), flat_values(&straight.model));
    assert_eq!(rest.best_val, straight.best_val);
    // Control: a resume that skipped the optimizer state would differ.
    let dir2 = tmpdir("resume-noopt");
    let _ = train(&data, &first, Some(&dir2), false);
    std::fs::remove_file(dir2.join("optimizer.bpk")).unwrap();
    let broken = train(&data, &o, Some(&dir2), true);
    assert_ne!(flat_values(&broken.model), flat_values(&straight.model));
    // A resume with other options is refused.
    let mut other = o.clone();
    other.seed = 6;
    let m = initial_model(&other, None, None, &crate::cpu_training_device()).unwrap();
    assert!(matches!(run(&data, &other, m, Some(&dir), true, &mut |_| {}), Err(TrainError::Checkpoint(_))));
}

/// Same seed → same trained weights; another seed → different ones. Guided joint stage from
/// scratch (Full-N-Full), so every network and both learning-rate groups take part.
#[test]
fn same_seed_same_weights() {
    let data = dataset();
    let o = options(Method::Guided, Some(Ablation::FullNFull), &short());
    let a = flat_values(&train(&data, &o, None, false).model);
    let b = flat_values(&train(&data, &o, None, false).model);
    assert_eq!(a, b);
    let mut o2 = o.clone();
    o2.seed = 77;
    assert_ne!(a, flat_values(&train(&data, &o2, None, false).model));
}

/// Thread count must not change the result (flex splits work over rayon; a reduction whose
/// order depended on the split would show up here as differing low bits).
#[test]
fn same_weights_with_one_or_two_threads() {
    let data = dataset();
    let o = options(Method::Guided, Some(Ablation::FullNFull), &short());
    let pool = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
    let a = pool(1).install(|| flat_values(&train(&data, &o, None, false).model));
    let b = pool(2).install(|| flat_values(&train(&data, &o, None, false).model));
    let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert_eq!(differing, 0, "{differing} of {} weights differ between 1 and 2 threads", a.len());
}

/// Fix-N-Train changes only E; the joint stage of the guided method changes E and the rest.
#[test]
fn fix_n_train_updates_only_e() {
    let data = dataset();
    let dev = crate::cpu_training_device();
    let o = options(Method::Guided, Some(Ablation::FixNTrain), &short());
    let mut cfg = o.config.clone();
    cfg.seed = o.seed;
    let before = MethodModel::init(&cfg, Method::Guided, &dev);
    let after = run(&data, &o, MethodModel::init(&cfg, Method::Guided, &dev), None, false, &mut |_| {}).unwrap().model;
    let p = |m: &MethodModel| checkpoint::parameters(m).into_iter().map(|(n, _, _, v)| (n, v)).collect::<Vec<_>>();
    for ((name, v0), (_, v1)) in p(&before).into_iter().zip(p(&after)) {
        let is_e = name.starts_with("diffuse.e.") || name.starts_with("specular.e.");
        assert_eq!(v0 != v1, is_e, "{name}: changed = {}", v0 != v1);
    }
}

/// A batch whose target is infinite gives a non-finite loss: training stops with an error
/// naming the stage, step, spp and the shots and corners of the batch.
#[test]
fn non_finite_loss_names_the_batch() {
    let mut data = dataset();
    for s in &mut data.train {
        s.target.diffuse.iter_mut().for_each(|v| *v = f32::INFINITY);
    }
    let o = options(Method::G, None, &short());
    let m = initial_model(&o, None, None, &crate::cpu_training_device()).unwrap();
    let err = run(&data, &o, m, None, false, &mut |_| {}).err().expect("must abort");
    let msg = err.to_string();
    assert!(matches!(err, TrainError::NonFinite { step: 0, .. }), "{msg}");
    let (refs, _) = draw_batch(&data, &o, 0, 0);
    for r in &refs {
        assert!(msg.contains(&format!("{} @({},{})", data.train[r.shot].name, r.x, r.y)), "{msg}");
    }
}

/// Weights written and read back are identical, and a file for another method is refused.
#[test]
fn weights_round_trip_and_mismatch() {
    let dev = crate::cpu_training_device();
    let cfg = tiny();
    let g = MethodModel::init(&cfg, Method::G, &dev);
    let path = tmpdir("weights").join("g.safetensors");
    checkpoint::save_weights(&path, &g, &BTreeMap::from([("method".to_string(), "g".to_string())])).unwrap();
    let fresh = MethodModel::init(&cfg.clone().with_seed(9), Method::G, &dev);
    assert_ne!(flat_values(&fresh), flat_values(&g));
    let (back, meta) = checkpoint::load_weights(&path, fresh, None).unwrap();
    assert_eq!(flat_values(&back), flat_values(&g));
    assert_eq!(meta.get("method").map(String::as_str), Some("g"));
    assert!(checkpoint::load_weights(&path, MethodModel::init(&cfg, Method::P, &dev), None).is_err());
}

/// Guided from G and P weight files: D_G comes from the G file, D_P and the PathNet from the P
/// file, and after the joint stage all of them and E have moved (so the loaded networks are
/// trainable, not frozen by loading). A G file given as --from-p is refused.
#[test]
fn guided_starts_from_pretrained_files_and_trains_them() {
    let data = dataset();
    let dev = crate::cpu_training_device();
    let dir = tmpdir("pretrained");
    let o = options(Method::Guided, None, &short());
    let cfg = effective_config(&o);
    let save = |m: Method, seed: u64| {
        let path = dir.join(format!("{m}.safetensors"));
        let model = MethodModel::init(&cfg.clone().with_seed(seed), m, &dev);
        crate::weights::save(&path, &model, &cfg, "tiny", &Default::default()).unwrap();
        // Files hold f16: compare against what the file holds, not the f32 model.
        let stored = crate::weights::load(&path, &dev).unwrap().model;
        assert_ne!(flat_values(&stored), flat_values(&MethodModel::init(&cfg.clone().with_seed(seed + 100), m, &dev)));
        (path, stored)
    };
    let (gp, g) = save(Method::G, 11);
    let (pp, p) = save(Method::P, 12);
    let start = initial_model(&o, Some(&gp), Some(&pp), &dev).unwrap();
    let vals = |m: &Option<_>| {
        m.as_ref().map(|x: &crate::column::Column| checkpoint::parameters(x).into_iter().flat_map(|t| t.3).collect::<Vec<f32>>())
    };
    assert_eq!(vals(&start.diffuse.d_g), vals(&g.diffuse.d_g));
    assert_eq!(vals(&start.specular.d_p), vals(&p.specular.d_p));
    let path_vals =
        |m: &MethodModel| checkpoint::parameters(m.diffuse.path.as_ref().unwrap()).into_iter().flat_map(|t| t.3).collect::<Vec<f32>>();
    assert_eq!(path_vals(&start), path_vals(&p));
    let e0 = checkpoint::parameters(start.diffuse.e.as_ref().unwrap()).into_iter().flat_map(|t| t.3).collect::<Vec<f32>>();
    let end = run(&data, &o, start, None, false, &mut |_| {}).unwrap().model;
    assert_ne!(vals(&end.diffuse.d_g), vals(&g.diffuse.d_g));
    assert_ne!(vals(&end.specular.d_p), vals(&p.specular.d_p));
    assert_ne!(path_vals(&end), path_vals(&p));
    assert_ne!(checkpoint::parameters(end.diffuse.e.as_ref().unwrap()).into_iter().flat_map(|t| t.3).collect::<Vec<f32>>(), e0);
    assert!(matches!(initial_model(&o, Some(&gp), Some(&gp), &dev), Err(TrainError::Options(_))));
}

/// A both-buffers run can continue from a both file (the file's weights, not fresh ones), and
/// is refused a G file or the guided method by name.
#[test]
fn both_warm_starts_from_its_own_kind_only() {
    let dev = crate::cpu_training_device();
    let dir = tmpdir("warm-both");
    let o = options(Method::Both, None, &short());
    let cfg = effective_config(&o);
    let save = |m: Method, seed: u64| {
        let path = dir.join(format!("{m}.safetensors"));
        crate::weights::save(&path, &MethodModel::init(&cfg.clone().with_seed(seed), m, &dev), &cfg, "tiny", &Default::default()).unwrap();
        path
    };
    let (both, g) = (save(Method::Both, 21), save(Method::G, 22));
    let stored = crate::weights::load(&both, &dev).unwrap().model;
    let warm = warm_start(&o, &both, &dev).unwrap();
    assert_eq!(flat_values(&warm), flat_values(&stored));
    assert_ne!(flat_values(&warm), flat_values(&initial_model(&o, None, None, &dev).unwrap()));
    let err = warm_start(&o, &g, &dev).expect_err("a G file cannot start a both run");
    assert!(err.to_string().contains("g.safetensors") && err.to_string().contains("expected both"), "{err}");
    assert!(warm_start(&options(Method::Guided, None, &short()), &both, &dev).is_err());
}

/// A guided finetune (`guided_finetune_steps`) continues a whole guided file, E included, and
/// trains every part of it on the blended radiance; an ablation cannot warm-start from it.
#[test]
fn guided_finetune_continues_a_guided_file_and_trains_all_of_it() {
    let data = dataset();
    let dev = crate::cpu_training_device();
    let dir = tmpdir("guided-finetune");
    let sched = ScheduleOptions { joint_steps: 0, guided_finetune_steps: 3, lr_finetune: 1e-3, ..short() };
    let o = options(Method::Guided, None, &sched);
    let kinds: Vec<_> = o.stages.iter().map(|s| (s.kind, s.steps, s.lr_e.is_some(), s.lr_rest.is_some())).collect();
    assert_eq!(kinds, [(StageKind::Joint, 0, true, true), (StageKind::Finetune, 3, true, true)]);
    assert_eq!(schedule::plan(Method::Guided, None, &short()).len(), 1, "the paper's schedule has no guided finetune");
    let cfg = effective_config(&o);
    let path = dir.join("guided.safetensors");
    std::fs::create_dir_all(&dir).unwrap();
    crate::weights::save(&path, &MethodModel::init(&cfg.clone().with_seed(31), Method::Guided, &dev), &cfg, "tiny", &Default::default())
        .unwrap();
    let stored = crate::weights::load(&path, &dev).unwrap().model;
    let start = warm_start(&o, &path, &dev).unwrap();
    assert_eq!(flat_values(&start), flat_values(&stored));
    let e_before = e_values(&start);
    let before = flat_values(&start);
    let end = run(&data, &o, start, None, false, &mut |_| {}).unwrap();
    assert!(end.best_val.is_some_and(f64::is_finite));
    let after = flat_values(&end.model);
    assert_ne!(e_values(&end.model), e_before, "E must train in the guided finetune");
    let moved = before.iter().zip(&after).filter(|(a, b)| a != b).count();
    assert!(moved > e_before.len(), "the columns must train too: {moved} values moved, E has {}", e_before.len());
    let ro = options(Method::Guided, Some(Ablation::RadianceOnly), &sched);
    let err = warm_start(&ro, &path, &dev).expect_err("an ablation starts from G and P files");
    assert!(err.to_string().contains("guided.safetensors"), "{err}");
}

fn e_values(model: &MethodModel) -> Vec<f32> {
    let only_e = |b: &BranchNets| BranchNets { d_g: None, d_p: None, d_gp: None, path: None, e: b.e.clone() };
    flat_values(&MethodModel { diffuse: only_e(&model.diffuse), specular: only_e(&model.specular) })
}

/// A guided model may join a D_G trained wider than its D_P (`p_widths`): each column loads
/// from a file of its own widths, a P file of the D_G's widths is refused by name, the joint
/// stage trains the mixed model, and its weight file loads back with both widths.
#[test]
fn guided_joins_a_wider_d_g_with_a_narrower_d_p() {
    let data = dataset();
    let dev = crate::cpu_training_device();
    let dir = tmpdir("mixed-widths");
    let column = |w: Vec<usize>| Some(MsKpConfig::new(34).with_widths(w).with_kernel_scales(2).with_filter_size(3).with_margin(2));
    let (wide, narrow) = (vec![8, 10, 12], vec![6, 8, 8]);
    let mut o = options(Method::Guided, None, &short());
    o.config = tiny().with_mskp(column(wide.clone())).with_p_widths(Some(narrow.clone()));
    let save = |m: Method, widths: &[usize]| {
        let cfg = tiny().with_mskp(column(widths.to_vec()));
        let path = dir.join(format!("{m}-{}.safetensors", widths[0]));
        crate::weights::save(&path, &MethodModel::init(&cfg, m, &dev), &cfg, "tiny", &Default::default()).unwrap();
        path
    };
    let (g_wide, p_narrow, p_wide) = (save(Method::G, &wide), save(Method::P, &narrow), save(Method::P, &wide));
    let err = initial_model(&o, Some(&g_wide), Some(&p_wide), &dev).expect_err("a P file of D_G's widths must be refused");
    assert!(err.to_string().contains(&*p_wide.to_string_lossy()), "{err}");
    let start = initial_model(&o, Some(&g_wide), Some(&p_narrow), &dev).unwrap();
    let end = run(&data, &o, start, None, false, &mut |_| {}).unwrap();
    assert!(end.best_val.is_some_and(f64::is_finite));
    let path = dir.join("guided.safetensors");
    let cfg = effective_config(&o);
    crate::weights::save(&path, &end.model, &cfg, "tiny", &Default::default()).unwrap();
    let back = crate::weights::load(&path, &dev).unwrap();
    assert_eq!(back.config.mskp_for(Variant::G).unwrap().widths, wide);
    assert_eq!(back.config.mskp_for(Variant::P).unwrap().widths, narrow);
    assert_eq!(checkpoint::parameters(&back.model).len(), checkpoint::parameters(&end.model).len());
}

/// A stage cut short by `--minutes` validates its last step, so the steps after the last
/// periodic validation count (the stage keeps its best validated weights). Here validation is
/// only periodic every 1000 steps and the budget (1 s) ends the stage long before that: the
/// run must still end with a validation at its last step and a best validation error. Before
/// the fix such a run kept the weights of its last periodic validation, or none at all.
#[test]
fn time_budget_validates_the_last_step() {
    let data = dataset();
    // The finetune stage's deadline is (almost) the branch stage's, so it starts past it and
    // takes no step: the run's best must stay the branch stage's.
    let sched = ScheduleOptions { branch_steps: 1_000_000, finetune_steps: 1, ..short() };
    let mut o = options(Method::G, None, &sched);
    o.val_every = 1000;
    o.minutes = Some(1.0 / 60.0);
    let m = initial_model(&o, None, None, &crate::cpu_training_device()).unwrap();
    let (mut validated, mut ended) = (Vec::new(), None);
    let out = run(&data, &o, m, None, false, &mut |e| match e {
        Event::Validation { step, .. } => validated.push(step),
        Event::StageEnd { index: 0, steps, reason } => ended = Some((steps, reason.to_string())),
        _ => {}
    })
    .unwrap();
    let (steps, reason) = ended.expect("the stage ended");
    assert_eq!(reason, "time budget");
    assert!(steps > 0 && steps < 1000, "{steps} steps");
    assert_eq!(validated, vec![steps], "validated at {validated:?}, stage ended at {steps}");
    assert!(out.best_val.is_some(), "a stage without steps dropped the previous stage's best");
}

/// `pixguide calibrate`'s search: one validation per exponent, the same score at 2 spp whatever
/// the exponent (the gain is 1 there), different scores at 4 spp (it is not), the lowest kept and
/// left set on the model; and the per-spp validation agrees with [`validate`].
#[test]
fn calibration_scores_each_exponent_and_keeps_the_lowest() {
    let data = dataset();
    let unet = MsKpConfig::new(34)
        .with_widths(vec![4, 6])
        .with_kernel_scales(2)
        .with_filter_size(3)
        .with_margin(1)
        .with_edge_stopping(EdgeStopping::FeaturesAndFadingNoisyColourDoubtingBlack);
    let mut o = options(Method::G, None, &short());
    o.config = tiny().with_mskp(Some(unet));
    let mut model = MethodModel::init(&o.config, Method::G, &o.backend.training_device().unwrap());
    let plain = validate(&model, &data, &o).unwrap().unwrap();
    let by = validate_by_spp(&model, &data, &o).unwrap().unwrap();
    assert_eq!(by.overall, plain);
    assert!((by.by_spp.iter().sum::<f64>() / by.by_spp.len() as f64 - plain).abs() < 1e-9 * plain, "{by:?} against {plain}");
    let exps = [0.0, 2.0, 4.0];
    let mut heard = Vec::new();
    let cal = calibrate::calibrate_guide_gain(&mut model, &data, &o, &exps, &mut |g, _| heard.push(g)).unwrap().unwrap();
    assert_eq!(heard, exps);
    assert_eq!(cal.tried[0].1, by, "γ = 0 is the model as it was");
    let at2: Vec<f64> = cal.tried.iter().map(|t| t.1.by_spp[0]).collect();
    assert!(at2.iter().all(|v| *v == at2[0]), "2 spp must not depend on γ: {at2:?}");
    let at4: Vec<f64> = cal.tried.iter().map(|t| t.1.by_spp[1]).collect();
    assert!(at4[0] != at4[2], "4 spp must depend on γ: {at4:?}");
    let lowest = cal.tried.iter().map(|t| t.1.overall).fold(f64::INFINITY, f64::min);
    let kept = cal.tried.iter().find(|t| t.0 == cal.best).unwrap();
    assert_eq!(kept.1.overall, lowest);
    let set = model.diffuse.d_g.as_ref().and_then(|c| c.unet.as_ref()).map(|u| u.guide_gain_exponent);
    assert_eq!(set, Some(cal.best));
}

#[test]
fn descriptors_read_from_their_file_equal_the_planes_in_memory() {
    // `prepare` normalises a frame's descriptors into planes; training reads the same values
    // from the dataset's file, patch by patch, for any prefix of the samples and any pixels.
    let mut rng = SplitMix64::new(5);
    let mut d = Descriptors::new(7, 5, 8);
    d.data.iter_mut().for_each(|v| *v = (rng.next_f64() as f32 - 0.1) * 1e3);
    d.data[3] = f32::NAN;
    for precision in [film::Precision::F32, film::Precision::Bf16] {
        let path = std::env::temp_dir().join(format!("pixguide-desc-eq-{precision:?}-{}.safetensors", std::process::id()));
        d.write_safetensors_as(&path, precision).unwrap();
        let whole = Descriptors::read_safetensors(&path).unwrap();
        let file = film::DescriptorFile::open(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        // Pixels of the 3×3 region at (2, 1) of the 7-wide image, in any order and repeated.
        let pixels: Vec<usize> = vec![23, 9, 11, 11, 16, 10, 25];
        for s in [1, 3, 8] {
            let region = data::Region::read(&file, s, 2, 1, 3, 7).unwrap();
            let from_file = augment::DescriptorSource::columns(&region, &pixels);
            let in_memory = crate::preprocess::normalised_columns(&whole, s, &pixels);
            assert_eq!(from_file, in_memory, "{precision:?}, {s} spp");
            assert!(from_file.iter().all(|v| v.is_finite()));
        }
    }
}

/// A packed checkpoint (f16 weights, Adam's second moment in 8 bits and its first left out) is
/// 5 bytes a parameter against the folder's 16, unpacks to a folder `--resume` continues from,
/// and the finished run is the uninterrupted one up to the roundings: weights within 1 % of
/// their spread, against a resume with no optimizer state, which lands further away.
#[test]
fn packed_checkpoint_resumes_close_to_the_uninterrupted_run() {
    let data = dataset();
    let o = options(Method::G, None, &short());
    let straight = flat_values(&train(&data, &o, Some(&tmpdir("pack-straight")), false).model);
    let dir = tmpdir("pack-half");
    let mut first = o.clone();
    first.pause_after = Some(3);
    assert!(train(&data, &first, Some(&dir), false).paused);
    let size = |d: &Path| std::fs::read_dir(d).unwrap().flatten().map(|e| e.metadata().unwrap().len()).sum::<u64>();
    let packed = tmpdir("pack-packed");
    let bytes = pack::pack(&dir, &packed).unwrap();
    // 5/16 of the tensor bytes, plus headers and state.json, which weigh more in this tiny model.
    assert!(bytes < size(&dir) / 2, "{bytes} of {}", size(&dir));
    let restored = tmpdir("pack-restored");
    pack::unpack(&packed, &restored).unwrap();
    // The unpacked weights are the paused run's within f16 rounding.
    let (paused, _) = checkpoint::read_weights(&dir.join("model.safetensors")).unwrap();
    let (unpacked, _) = checkpoint::read_weights(&restored.join("model.safetensors")).unwrap();
    assert_eq!(paused.len(), unpacked.len());
    for (name, (shape, v)) in &paused {
        let (s, u) = &unpacked[name];
        assert_eq!(shape, s, "{name}");
        for (a, b) in v.iter().zip(u) {
            assert!((a - b).abs() <= a.abs() * 2f32.powi(-11) + 6e-8, "{name}: {a} -> {b}");
        }
    }
    let resumed = flat_values(&train(&data, &o, Some(&restored), true).model);
    let rms = |a: &[f32], b: &[f32]| (a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
    let spread = rms(&straight, &vec![0.0; straight.len()]);
    let off = rms(&resumed, &straight);
    assert!(off < 0.01 * spread, "packed resume {off} from the straight run (spread {spread})");
    // Without the optimizer state (the alternative to packing it), Adam restarts.
    let bare = tmpdir("pack-bare");
    pack::unpack(&packed, &bare).unwrap();
    std::fs::remove_file(bare.join("optimizer.bpk")).unwrap();
    let restarted = flat_values(&train(&data, &o, Some(&bare), true).model);
    assert!(rms(&restarted, &straight) > off, "restart {} vs packed {off}", rms(&restarted, &straight));
    // Not a checkpoint folder: an error naming the file.
    let e = pack::pack(&tmpdir("pack-empty"), &tmpdir("pack-out")).unwrap_err().to_string();
    assert!(e.contains("model.safetensors"), "{e}");
}

/// A session's time limit pauses the run with a checkpoint instead of cutting its schedule:
/// resumed, it takes every planned step and ends where an uninterrupted run ends.
#[test]
fn session_minutes_pause_without_cutting_the_schedule() {
    let data = dataset();
    let o = options(Method::G, None, &short());
    let straight = train(&data, &o, None, false);
    let dir = tmpdir("session-minutes");
    let mut first = o.clone();
    first.pause_after = Some(2);
    assert!(train(&data, &first, Some(&dir), false).paused);
    let mut timed_out = o.clone();
    timed_out.pause_after_minutes = Some(0.0);
    let paused = train(&data, &timed_out, Some(&dir), true);
    assert!(paused.paused && paused.total_steps == 2, "{}", paused.total_steps);
    let rest = train(&data, &o, Some(&dir), true);
    assert_eq!(rest.total_steps, straight.total_steps);
    assert_eq!(flat_values(&rest.model), flat_values(&straight.model));
}

/// A descriptor file that goes bad under a running training (here: truncated after it was
/// opened) ends the run with an error naming the shot, not a panic.
#[test]
fn unreadable_descriptors_are_an_error_naming_the_shot() {
    let mut data = dataset();
    let path = std::env::temp_dir().join(format!("pixguide-train-truncated-{}.safetensors", std::process::id()));
    let d = Descriptors::new(W as u32, W as u32, 4);
    d.write_safetensors(&path).unwrap();
    let file = film::DescriptorFile::open(&path).unwrap();
    std::fs::OpenOptions::new().write(true).open(&path).unwrap().set_len(200).unwrap();
    for s in data.train.iter_mut() {
        s.descriptors = Some(file.try_clone().unwrap());
    }
    let _ = std::fs::remove_file(&path);
    let o = options(Method::P, None, &short());
    let m = initial_model(&o, None, None, &crate::cpu_training_device()).unwrap();
    match run(&data, &o, m, None, false, &mut |_| {}) {
        Err(TrainError::Data(e)) => assert!(e.contains("train/s"), "{e}"),
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("trained on a truncated file"),
    }
}
