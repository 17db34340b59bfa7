//! Fuzz tests of the weight-file reader, `denoiser::weights::load`, fed the shipped weight files
//! mutated two ways (raw bytes anywhere, and edits of the JSON header re-framed with a matching
//! length, which reach the tensor table, the configuration and the provenance), and arbitrary
//! headers. It must return `Ok` or an error, never panic, hang or allocate beyond the cap (the
//! harness, shared with the renderer's fuzz tests: renderer/tests/fuzz_support/mod.rs).

#[path = "../../renderer/tests/fuzz_support/mod.rs"]
mod fuzz_support;

use fuzz_support::*;
use proptest::prelude::*;
use std::path::PathBuf;

#[global_allocator]
static ALLOC: CappedAlloc = CappedAlloc;

/// The shipped files of every method (g, p, both and guided) and of both sizes.
fn sources() -> Vec<PathBuf> {
    let dir = repo().join("denoiser/weights");
    let names = ["g-default", "p-default", "both-default", "guided-default", "g-half", "guided-half"];
    names.iter().map(|n| dir.join(format!("{n}.safetensors"))).collect()
}

fn load(p: PathBuf) -> Result<(), denoiser::weights::WeightsError> {
    denoiser::weights::load(&p, &denoiser::cpu_device()).map(|_| ())
}

/// (header, tensor data) of a safetensors file.
fn split(bytes: &[u8]) -> (Vec<u8>, Vec<u8>) {
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    (bytes[8..8 + n].to_vec(), bytes[8 + n..].to_vec())
}

fn frame(header: &[u8], data: &[u8]) -> Vec<u8> {
    let mut b = (header.len() as u64).to_le_bytes().to_vec();
    b.extend_from_slice(header);
    b.extend_from_slice(data);
    b
}

#[test]
fn mutated_weight_files_load_or_fail_cleanly() {
    let dir = scratch("weights");
    let sources = sources();
    let originals: Vec<Vec<u8>> = sources.iter().map(|s| std::fs::read(s).unwrap()).collect();
    let case = dir.join("case.safetensors");
    run_cases("weights", 64, 31, Inputs::Mutated, &mutated(sources.len()), |tally, (i, edits)| {
        std::fs::write(&case, apply_all(&originals[i], &edits)).unwrap();
        guarded(tally, label(&sources[i], &edits), {
            let p = case.clone();
            move || load(p)
        })
    });
}

#[test]
fn weight_files_with_mutated_headers_load_or_fail_cleanly() {
    let dir = scratch("weights_header");
    let sources = sources();
    let parts: Vec<(Vec<u8>, Vec<u8>)> = sources.iter().map(|s| split(&std::fs::read(s).unwrap())).collect();
    let case = dir.join("case.safetensors");
    run_cases("weights (header)", 160, 32, Inputs::Mutated, &mutated(sources.len()), |tally, (i, edits)| {
        let (header, data) = &parts[i];
        std::fs::write(&case, frame(&apply_all(header, &edits), data)).unwrap();
        guarded(tally, format!("header of {}", label(&sources[i], &edits)), {
            let p = case.clone();
            move || load(p)
        })
    });
}

/// The metadata values themselves mutated (the configuration's JSON above all), the header
/// re-serialised around them: edits that reach `check_config` and the model's constructors
/// rather than the JSON parser.
#[test]
fn weight_files_with_mutated_metadata_load_or_fail_cleanly() {
    let dir = scratch("weights_metadata");
    let sources = sources();
    let parts: Vec<(serde_json::Value, Vec<u8>)> = sources
        .iter()
        .map(|s| {
            let (h, d) = split(&std::fs::read(s).unwrap());
            (serde_json::from_slice(&h).unwrap(), d)
        })
        .collect();
    const KEYS: &[&str] =
        &["pixguide.config", "pixguide.config", "pixguide.config", "pixguide.provenance", "pixguide.method", "pixguide.format"];
    let case = dir.join("case.safetensors");
    run_cases(
        "weights (metadata)",
        192,
        34,
        Inputs::Mutated,
        &(mutated(sources.len()), prop::sample::select(KEYS)),
        |tally, ((i, edits), key)| {
            let (header, data) = &parts[i];
            let mut header = header.clone();
            let value = header["__metadata__"][key].as_str().unwrap().as_bytes().to_vec();
            header["__metadata__"][key] = serde_json::Value::String(String::from_utf8_lossy(&apply_all(&value, &edits)).into_owned());
            std::fs::write(&case, frame(&serde_json::to_vec(&header).unwrap(), data)).unwrap();
            guarded(tally, format!("{key} of {}", label(&sources[i], &edits)), {
                let p = case.clone();
                move || load(p)
            })
        },
    );
}

const TOKENS: &[&str] = &[
    "{",
    "}",
    "[",
    "]",
    ",",
    ":",
    "\"__metadata__\"",
    "\"pixguide.format\"",
    "\"1\"",
    "\"pixguide.method\"",
    "\"g\"",
    "\"guided\"",
    "\"pixguide.config\"",
    "\"{\\\"kpcn\\\": {}}\"",
    "\"dtype\"",
    "\"F16\"",
    "\"F32\"",
    "\"I8\"",
    "\"pixguide.storage\"",
    "\"int8-rows\"",
    "\"diffuse.d_g.net.layers.0.weight.int8_scale\"",
    "\"shape\"",
    "\"data_offsets\"",
    "[0, 2]",
    "[1]",
    "\"diffuse.d_g.net.layers.0.weight\"",
    "0",
    "2",
];

#[test]
fn arbitrary_weight_headers_fail_cleanly() {
    let dir = scratch("weights_soup");
    let case = dir.join("case.safetensors");
    let input = (token_soup(TOKENS, 64), prop::collection::vec(any::<u8>(), 0..64));
    run_cases("weights (arbitrary)", 128, 33, Inputs::Arbitrary, &input, |tally, (header, data)| {
        std::fs::write(&case, frame(&header, &data)).unwrap();
        guarded(tally, format!("header {:?}", String::from_utf8_lossy(&header)), {
            let p = case.clone();
            move || load(p)
        })
    });
}
