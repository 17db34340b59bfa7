//! Seconds per training step of every stage of the comparison, on real dataset batches,
//! interleaved round-robin so that all variants see the same machine load.
//!
//! `cargo run --release -p denoiser --example train_bench -- DATA [rounds] [batch] [patch]`
//! (defaults 4 rounds, batch 4, patch 64). Prints the median and minimum per variant.

use std::time::Instant;

use denoiser::method::{Method, MethodModel};
use denoiser::model::Preset;
use denoiser::train::data::{batch_tensors, Dataset, LoadOptions};
use denoiser::train::patches::Sampling;
use denoiser::train::schedule::{Stage, StageKind};
use denoiser::train::{draw_batch, optimizer, train_step, TrainOptions};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let data_dir = args.first().expect("usage: train_bench DATA [rounds] [batch] [patch]");
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (rounds, batch, patch) = (num(1, 4), num(2, 4), num(3, 64));
    let load = LoadOptions { spps: vec![], descriptors: true, patch, sampling: Sampling::Importance, max_train: None };
    let data = Dataset::load(std::path::Path::new(data_dir), &load, &mut |_, _| {}).unwrap();
    let dev = denoiser::cpu_training_device();
    let stage = |kind, rest: Option<f64>, e: Option<f64>, w| Stage::constant(kind, 1, rest, e, w);
    let variants: Vec<(&str, Preset, Method, Stage, bool)> = vec![
        ("g branches", Preset::Default, Method::G, stage(StageKind::Branches, Some(1e-4), None, 0.0), false),
        ("g finetune", Preset::Default, Method::G, stage(StageKind::Finetune, Some(1e-6), None, 0.0), false),
        ("p branches", Preset::Default, Method::P, stage(StageKind::Branches, Some(1e-4), None, 0.1), false),
        ("p finetune", Preset::Default, Method::P, stage(StageKind::Finetune, Some(1e-6), None, 0.0), false),
        ("both branches", Preset::Default, Method::Both, stage(StageKind::Branches, Some(1e-4), None, 0.1), false),
        ("both finetune", Preset::Default, Method::Both, stage(StageKind::Finetune, Some(1e-6), None, 0.0), false),
        ("guided joint", Preset::Default, Method::Guided, stage(StageKind::Joint, Some(1e-6), Some(1e-5), 0.1), false),
        ("fix-n-train joint", Preset::Default, Method::Guided, stage(StageKind::Joint, None, Some(1e-5), 0.0), false),
        ("radiance-only joint", Preset::Default, Method::Guided, stage(StageKind::Joint, Some(1e-6), Some(1e-5), 0.1), true),
        ("g-half branches", Preset::Half, Method::G, stage(StageKind::Branches, Some(1e-4), None, 0.0), false),
        ("p-half branches", Preset::Half, Method::P, stage(StageKind::Branches, Some(1e-4), None, 0.1), false),
        ("guided-half joint", Preset::Half, Method::Guided, stage(StageKind::Joint, Some(1e-6), Some(1e-5), 0.1), false),
    ];
    let mut state: Vec<_> = variants
        .iter()
        .map(|(_, preset, m, st, rad)| {
            let mut cfg = preset.config();
            cfg.ensemble.radiance_only = *rad;
            let mut model = MethodModel::init(&cfg, *m, &dev);
            if st.lr_rest.is_none() {
                for b in [&mut model.diffuse, &mut model.specular] {
                    b.d_g = b.d_g.take().map(denoiser::burn::module::Module::no_grad);
                    b.d_p = b.d_p.take().map(denoiser::burn::module::Module::no_grad);
                    b.path = b.path.take().map(denoiser::burn::module::Module::no_grad);
                }
            }
            let opts = TrainOptions { seed: 1, augment: true, ..TrainOptions::new(*m, cfg, patch, batch, vec![st.clone()]) };
            (Some(model), optimizer(), opts, Vec::<f64>::new())
        })
        .collect();
    for round in 0..=rounds {
        for (v, (model, optim, opts, times)) in variants.iter().zip(state.iter_mut()) {
            let st = &v.3;
            let e_ids: Vec<_> = {
                // E parameters: every parameter of the ensembling nets.
                let m = model.as_ref().unwrap();
                let mut ids = Vec::new();
                for b in [&m.diffuse, &m.specular] {
                    if let Some(e) = &b.e {
                        ids.extend(denoiser::train::checkpoint::parameters(e).into_iter().map(|p| p.1));
                    }
                }
                ids
            };
            let t0 = Instant::now();
            let (refs, mut rng) = draw_batch(&data, opts, 0, round);
            let (input, target) = batch_tensors(&data.train, &refs, &data.spps, patch, opts.config.margin(), v.2.needs_descriptors(), &dev)
                .expect("reading the batch");
            let (m, _) = train_step(model.take().unwrap(), optim, input, &target, st, 1.0, &e_ids, &mut rng).unwrap();
            *model = Some(m);
            if round > 0 {
                times.push(t0.elapsed().as_secs_f64());
            }
        }
    }
    println!("batch {batch} × {patch}², spp drawn from {:?}, {rounds} rounds (after 1 warm-up)", data.spps);
    for (v, s) in variants.iter().zip(&state) {
        let mut t = s.3.clone();
        t.sort_by(f64::total_cmp);
        println!("{:<22} median {:>6.2} s/step  min {:>6.2}", v.0, t[t.len() / 2], t[0]);
    }
}
