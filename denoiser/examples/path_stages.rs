//! Times the path-manifold module's stages on random descriptors: the whole-image forward vs
//! the per-sample stages over pixel chunks of different shapes.
//!
//! `cargo run --release -p denoiser --example path_stages -- [size] [spp] [chunk]`
//!
//! With `BREAKDOWN=size,spp` it instead runs `infer::denoise` of a random guided `default` model
//! on a random image (automatic tile, then one window) and prints the `Timings`.

use std::time::Instant;

use denoiser::burn::tensor::{Distribution, Tensor};
use denoiser::model::DenoiserConfig;
use denoiser::pathnet::PathNet;

fn main() {
    if let Ok(v) = std::env::var("BREAKDOWN") {
        let v: Vec<usize> = v.split(',').map(|x| x.parse().unwrap()).collect();
        return denoise_breakdown(v[0], v[1]);
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (size, s, chunk) = (num(0, 272), num(1, 8), num(2, 1 << 17));
    let d = denoiser::cpu_device();
    let net = DenoiserConfig::kpcn_cpu().pathnet.init(1, &d);
    let u = Distribution::Uniform(0.0, 1.0);
    let x: Tensor<5> = Tensor::random([1, s, 36, size, size], u, &d);
    let sync = |t: Tensor<4>| t.into_data();
    let t = Instant::now();
    let _ = sync(net.forward(x.clone()).pixel_buffer());
    println!("forward whole: {:.2} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let e = net.embed(x.clone());
    let _ = sync(PathNet::pixel_mean(&e));
    println!("embed+mean whole: {:.2} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let g = net.unet(PathNet::pixel_mean(&e));
    let g = Tensor::<4>::from_data(g.into_data(), &d);
    println!("unet whole: {:.2} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let _ = sync(net.head_pool(e, g.clone()).pixel_buffer());
    println!("head_pool whole: {:.2} s", t.elapsed().as_secs_f64());
    // Chunks of rows [1, S, 36, r, size] and flat chunks [1, S, 36, 1, n].
    let rows = (chunk / s / size).max(1);
    for flat in [false, true] {
        let (mut te, mut th) = (0.0, 0.0);
        for y0 in (0..size).step_by(rows) {
            let r = rows.min(size - y0);
            let xc = x.clone().narrow(3, y0, r);
            let gc = g.clone().narrow(2, y0, r);
            let (xc, gc) = if flat {
                let xc: Tensor<5> = Tensor::from_data(xc.into_data(), &d);
                (xc.reshape([1, s, 36, 1, r * size]), Tensor::<4>::from_data(gc.into_data(), &d).reshape([1, g.dims()[1], 1, r * size]))
            } else {
                (Tensor::from_data(xc.into_data(), &d), Tensor::from_data(gc.into_data(), &d))
            };
            let t = Instant::now();
            let e = net.embed(xc);
            let _ = sync(PathNet::pixel_mean(&e));
            te += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let e = net.embed(Tensor::<5>::random([1, s, 36, if flat { 1 } else { r }, if flat { r * size } else { size }], u, &d));
            let _ = sync(net.head_pool(e, gc).pixel_buffer());
            th += t.elapsed().as_secs_f64();
        }
        println!("chunked ({}) {rows} rows: embed+mean {te:.2} s, embed+head_pool {th:.2} s", if flat { "flat 1×n" } else { "rows" });
    }
}

fn denoise_breakdown(size: usize, s: usize) {
    use denoiser::infer::{denoise, InferOptions};
    use denoiser::method::{Method, MethodModel};
    use denoiser::preprocess::PreparedImage;
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
