//! Times the per-sample stages of the path-manifold module on random descriptors, side by side
//! in one process: as tensor ops on the whole image (`PathNet::embed`, `pixel_mean`,
//! `head_pool`: what inference ran before) and fused on the host (`infer::PathMlp`: what it runs
//! now), with the ratio. Rounds interleave the two.
//!
//! `cargo run --release -p denoiser --example path_stages -- [size] [spp] [preset] [rounds]`
//! (preset: default or kpcn)
//!
//! With `BREAKDOWN=size,spp` it instead runs `infer::denoise` of a random guided `kpcn` model
//! on a random image (automatic tile, then one window) and prints the `Timings`.

use std::time::Instant;

use denoiser::burn::tensor::{Distribution, Tensor};
use denoiser::infer::PathMlp;
use denoiser::model::DenoiserConfig;
use denoiser::pathnet::PathNet;
use denoiser::preprocess::PreparedImage;

fn main() {
    if let Ok(v) = std::env::var("BREAKDOWN") {
        let v: Vec<usize> = v.split(',').map(|x| x.parse().unwrap()).collect();
        return denoise_breakdown(v[0], v[1]);
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (size, s) = (num(0, 256), num(1, 8));
    let preset = args.get(2).map_or("default", String::as_str);
    let rounds = num(3, 3);
    let cfg = if preset == "kpcn" { DenoiserConfig::kpcn_cpu() } else { DenoiserConfig::cpu_default() };
    let d = denoiser::cpu_device();
    let net = cfg.pathnet.init(1, &d);
    let x: Tensor<5> = Tensor::random([1, s, 36, size, size], Distribution::Uniform(0.0, 1.0), &d);
    let desc: Vec<f32> = x.clone().into_data().convert::<f32>().try_into_vec::<f32>().unwrap();
    let n = size * size;
    let image = PreparedImage {
        width: size,
        height: size,
        spp: s,
        diffuse: Vec::new(),
        specular: Vec::new(),
        g_block: Vec::new(),
        path_weight: Vec::new(),
        descriptors: Some(desc),
        records: None,
        passthrough: Vec::new(),
    };
    let g = net.unet(PathNet::pixel_mean(&net.embed(x.clone())));
    let gw = g.dims()[1];
    let g_host: Vec<f32> = g.clone().into_data().convert::<f32>().try_into_vec::<f32>().unwrap();
    let pixels: Vec<usize> = (0..n).collect();
    println!("{size}×{size}, {s} spp, {preset} PathNet, {} thread(s); seconds per round:", rayon::current_num_threads());
    let (mut tensor_s, mut host_s) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        let t = Instant::now();
        let e = net.embed(x.clone());
        let _ = PathNet::pixel_mean(&e).into_data();
        let e = net.embed(x.clone());
        let _ = net.head_pool(e, g.clone()).pixel_buffer().into_data();
        tensor_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let mlp = PathMlp::new(&net);
        let _ = mlp.mean_embedding(&image, &pixels);
        let _ = mlp.pixel_buffer(&image, &pixels, |p, out: &mut [f32]| {
            for (c, o) in out.iter_mut().enumerate() {
                *o = g_host[c * n + p];
            }
        });
        host_s.push(t.elapsed().as_secs_f64());
        assert_eq!(gw, g_host.len() / n);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (a, b) = (median(&mut tensor_s), median(&mut host_s));
    println!("tensor stages {a:.3} s, fused host stages {b:.3} s (medians of {rounds}): {:.1}× faster", a / b);
    println!("fused: {:.2} s per megapixel", b / (n as f64 / 1e6));
}

fn denoise_breakdown(size: usize, s: usize) {
    use denoiser::infer::{denoise, InferOptions};
    use denoiser::method::{Method, MethodModel};
    let d = denoiser::cpu_device();
    let cfg = DenoiserConfig::kpcn_cpu();
    let model = MethodModel::init(&cfg, Method::Guided, &d);
    let n = size * size;
    let mut k = 0u64;
    let mut r = |len: usize| -> Vec<f32> {
        (0..len)
            .map(|_| {
                k = k.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (k >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect()
    };
    let img = PreparedImage {
        width: size,
        height: size,
        spp: s,
        diffuse: r(10 * n),
        specular: r(10 * n),
        g_block: r(24 * n),
        path_weight: r(n),
        descriptors: Some(r(s * 36 * n)),
        records: None,
        passthrough: vec![false; n],
    };
    let noisy = vec![0.5; 3 * n];
    for tile in [0, 1000] {
        let out = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile, batch: 1 }, &d).unwrap();
        println!("tile {tile}: {:?}", out.timings);
    }
}
