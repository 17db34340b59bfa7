//! `pixguide`: render scenes and denoise them, train and evaluate the denoisers, from one program
//! (docs/architecture.md).

mod alloc_stats;
mod cli;
mod malloc_release;

#[global_allocator]
static ALLOC: alloc_stats::Counting = alloc_stats::Counting;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "pixguide", version, about = "CPU path tracer and neural Monte Carlo denoiser (pixel-wise guidance, Han et al. 2023)")]
struct Args {
    /// Worker threads (default: all cores). Images do not depend on it.
    #[arg(long, global = true)]
    threads: Option<usize>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
#[allow(clippy::large_enum_variant, reason = "parsed once per run; boxing the arguments would only add noise")]
enum Command {
    /// Render a scene (.toml, .gltf/.glb) to EXR, with an optional PNG preview.
    Render(cli::render::RenderArgs),
    /// Measure the integrator against Mitsuba 3, the BVH against Embree, and buffer costs; prints ratios against baselines run in the same process.
    Bench(cli::bench::BenchArgs),
    /// Time g, p, guided (on the inference engine and on burn) and Open Image Denoise on one
    /// rendered frame: s/MP, ratio to OIDN, peak resident memory, per-stage GMAC/s.
    BenchDenoise(cli::bench_denoise::BenchDenoiseArgs),
    /// Write a procedural sky (Preetham + sun) environment map to EXR.
    Sky(cli::sky::SkyArgs),
    /// Generate randomized training shots with references (resumable).
    Dataset(cli::dataset::DatasetArgs),
    /// Render the test scenes' high-spp references (resumable).
    Reference(cli::reference::ReferenceArgs),
    /// Train a denoiser (g, p, both, guided, ablations) on a dataset folder (resumable).
    Train(cli::train::TrainArgs),
    /// Train the ensembling network E (the gate) over frozen experts (g, p, and optionally OIDN):
    /// their outputs on every shot are computed once and cached, then only E trains.
    TrainGate(cli::train_gate::TrainGateArgs),
    /// Fit a trained model's guide gain (strengths × (N/2)^γ at N spp) on a dataset's
    /// validation shots and write the model with it; the tensors are unchanged.
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Pack a training checkpoint small enough to commit (f16 weights, 8-bit optimizer moments),
    /// or unpack one to continue the run on another machine.
    Checkpoint(cli::checkpoint::CheckpointArgs),
    /// Rewrite a trained weight file with its kernels in 8 bits (one scale per row): half the
    /// f16 file, for shipping.
    Quantize(cli::quantize::QuantizeArgs),
    /// Denoise a frame written by `render --aovs` (G, P, both-buffers or guided model).
    Denoise(cli::denoise::DenoiseArgs),
    /// Regenerate docs/results.md: every method on the test scenes at each spp — error tables,
    /// error-vs-spp and error-vs-time plots, runtime breakdown, pictures (resumable).
    Eval(cli::eval::EvalArgs),
    /// Plot validation relMSE of training runs (their `<weights>.log.jsonl`) against steps and
    /// wall time, and print a Markdown summary: best validation and where each curve flattens.
    ///
    /// The PNG has two panels, validation relMSE against total steps and against wall-time
    /// minutes, one curve per log, a ring at each run's best validation. The table on stdout
    /// gives per run its steps, wall minutes, best validation relMSE and its step and minute,
    /// and where the curve flattens: the first validation that no later validation improves on
    /// by more than 5 % (relative); "not yet" when only the last one qualifies. Logs whose
    /// validations carry no wall time (written before they did) take it from their summed step
    /// durations, which leave out validation; the legend and table say so.
    PlotTraining(cli::plot_training::PlotTrainingArgs),
}

fn main() {
    let args = Args::parse();
    if let Some(n) = args.threads {
        if let Err(e) = rayon::ThreadPoolBuilder::new().num_threads(n.max(1)).build_global() {
            eprintln!("warning: could not set the thread count: {e}");
        }
    }
    let result = match args.command {
        Command::Render(a) => cli::render::run(a),
        Command::Bench(a) => cli::bench::run(a),
        Command::BenchDenoise(a) => cli::bench_denoise::run(a),
        Command::Sky(a) => cli::sky::run(a),
        Command::Dataset(a) => cli::dataset::run(a),
        Command::Reference(a) => cli::reference::run(a),
        Command::Train(a) => cli::train::run(a),
        Command::TrainGate(a) => cli::train_gate::run(a),
        Command::Calibrate(a) => cli::calibrate::run(a),
        Command::Checkpoint(a) => cli::checkpoint::run(a),
        Command::Quantize(a) => cli::quantize::run(a),
        Command::Denoise(a) => cli::denoise::run(a),
        Command::Eval(a) => cli::eval::run(a),
        Command::PlotTraining(a) => cli::plot_training::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
