//! The harness of the fuzz_* tests (renderer/tests and, through `#[path]`, denoiser/tests): file
//! readers fed mutated copies of real files and arbitrary bytes must return `Ok` or `Err`.
//!
//! Three ways a reader can fail a case, and how each is caught:
//! - a panic: the reader runs on a worker thread under `catch_unwind`;
//! - a hang: the worker gets [`CASE_TIMEOUT`] and the case fails when it runs out;
//! - an absurd allocation: the test binary's global allocator ([`CappedAlloc`]) refuses any
//!   single allocation above [`MAX_ALLOCATION`], printing the case being read, and the process
//!   aborts (an allocation failure cannot be unwound, so the whole test binary fails).
//!
//! Seeds are fixed, so a run is reproducible; proptest shrinks a failing case to the fewest
//! mutations that still fail, and prints them.
#![allow(dead_code)]

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, RngSeed, TestRunner};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::RefCell;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// No input of these tests is larger than a few MB, and none of the real files needs more
/// than tens of MB in any single buffer; a reader asking for more than this from such an input
/// trusts a size field it should have checked.
pub const MAX_ALLOCATION: usize = 1 << 30;

/// Far beyond the slowest valid input here (the bunny scene: under a second in release).
pub const CASE_TIMEOUT: Duration = Duration::from_secs(60);

thread_local! {
    /// What the current thread is reading, for the allocator's report.
    static CASE: RefCell<String> = const { RefCell::new(String::new()) };
}

/// The global allocator of every fuzz test binary: the system allocator with a cap per
/// allocation.
pub struct CappedAlloc;

/// The case started last in this process, for allocations on threads of the reader's own
/// (the exr crate decodes on a thread pool), which have no `CASE`.
static LAST_CASE: std::sync::Mutex<String> = std::sync::Mutex::new(String::new());

#[cold]
fn refuse(size: usize) {
    let _ = CASE.try_with(|c| {
        if let Ok(c) = c.try_borrow() {
            if !c.is_empty() {
                let _ = writeln!(std::io::stderr(), "fuzz: refused an allocation of {size} bytes (cap {MAX_ALLOCATION}) while reading {c}");
            } else if let Ok(last) = LAST_CASE.try_lock() {
                let _ = writeln!(
                    std::io::stderr(),
                    "fuzz: refused an allocation of {size} bytes (cap {MAX_ALLOCATION}) on a helper thread; the last case started: {last}"
                );
            }
        }
    });
}

unsafe impl GlobalAlloc for CappedAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > MAX_ALLOCATION {
            refuse(layout.size());
            return std::ptr::null_mut();
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if layout.size() > MAX_ALLOCATION {
            refuse(layout.size());
            return std::ptr::null_mut();
        }
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > MAX_ALLOCATION {
            refuse(new_size);
            return std::ptr::null_mut();
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// How many cases of a test the reader accepted and refused. A mutation test where every case
/// is refused would only be exercising the first check of the format; one where every case is
/// accepted would be mutating nothing the reader looks at. `check` asserts neither happened.
#[derive(Default)]
pub struct Tally {
    accepted: std::sync::atomic::AtomicUsize,
    refused: std::sync::atomic::AtomicUsize,
}

impl Tally {
    /// For arbitrary inputs, which may all be refused.
    pub fn report(&self, name: &str) {
        let (a, r) = (self.accepted.load(std::sync::atomic::Ordering::Relaxed), self.refused.load(std::sync::atomic::Ordering::Relaxed));
        eprintln!("{name}: {a} cases accepted, {r} refused");
    }

    pub fn check(&self, name: &str) {
        let (a, r) = (self.accepted.load(std::sync::atomic::Ordering::Relaxed), self.refused.load(std::sync::atomic::Ordering::Relaxed));
        eprintln!("{name}: {a} cases accepted, {r} refused");
        assert!(a > 0 && r > 0, "{name}: {a} cases accepted and {r} refused; the inputs do not reach the reader as intended");
    }
}

/// Runs `read` on a worker thread labelled `case`: a panic or a run past [`CASE_TIMEOUT`] fails
/// the proptest case with the message; `Ok` and `Err` both pass (and are counted in `tally`).
/// With `PIXGUIDE_FUZZ_VERBOSE` set, every case and the reader's answer are printed.
pub fn guarded<T, E: std::fmt::Debug>(
    tally: &Tally,
    case: String,
    read: impl FnOnce() -> Result<T, E> + Send + 'static,
) -> Result<(), TestCaseError> {
    let (tx, rx) = std::sync::mpsc::channel();
    let label = case.clone();
    std::thread::Builder::new()
        .name("fuzz-case".into())
        .spawn(move || {
            let verbose = std::env::var_os("PIXGUIDE_FUZZ_VERBOSE").is_some();
            if verbose {
                eprintln!("fuzz: reading {label}");
            }
            if let Ok(mut last) = LAST_CASE.lock() {
                last.clone_from(&label);
            }
            CASE.with(|c| *c.borrow_mut() = label);
            let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match read() {
                Ok(_) => true,
                Err(e) => {
                    if verbose {
                        eprintln!("fuzz: refused: {e:?}");
                    }
                    false
                }
            }));
            let _ = tx.send(out.map_err(|p| panic_message(&p)));
        })
        .expect("spawn a worker thread");
    match rx.recv_timeout(CASE_TIMEOUT) {
        Ok(Ok(accepted)) => {
            let n = if accepted { &tally.accepted } else { &tally.refused };
            n.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            Ok(())
        }
        Ok(Err(message)) => Err(TestCaseError::fail(format!("{case}: the reader panicked: {message}"))),
        // The worker is left running: it cannot be stopped, and the test fails anyway.
        Err(_) => Err(TestCaseError::fail(format!("{case}: no answer within {CASE_TIMEOUT:?} (a hang?)"))),
    }
}

fn panic_message(p: &Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| p.downcast_ref::<String>().cloned()).unwrap_or_else(|| "(no message)".into())
}

/// A fixed seed per test (different tests get different ones through `salt`), no regression
/// files written into the source tree, and a bounded shrink (a hang costs [`CASE_TIMEOUT`] per
/// shrink step).
pub fn config(cases: u32, salt: u64) -> Config {
    Config {
        cases,
        rng_seed: RngSeed::Fixed(0x5EED_F022 ^ salt),
        failure_persistence: None,
        max_shrink_iters: 256,
        max_shrink_time: 120_000,
        ..Config::default()
    }
}

/// What the cases of a run are, which decides what its tally must show.
#[derive(Clone, Copy, Debug)]
pub enum Inputs {
    /// Mutated copies of files the reader accepts: both answers must occur ([`Tally::check`]).
    Mutated,
    /// Arbitrary inputs, which may all be refused ([`Tally::report`]).
    Arbitrary,
}

/// One proptest run over `strategy` with [`config`]`(cases, salt)`: `case` gets each value and
/// the run's tally (for [`guarded`]). A failing case panics with `name` and proptest's shrunk
/// input; afterwards the tally is checked or reported, as `inputs` says.
pub fn run_cases<S: Strategy>(
    name: &str,
    cases: u32,
    salt: u64,
    inputs: Inputs,
    strategy: &S,
    case: impl Fn(&Tally, S::Value) -> Result<(), TestCaseError>,
) {
    let tally = Tally::default();
    let mut runner = TestRunner::new(config(cases, salt));
    if let Err(e) = runner.run(strategy, |value| case(&tally, value)) {
        panic!("{name}: {e}");
    }
    match inputs {
        Inputs::Mutated => tally.check(name),
        Inputs::Arbitrary => tally.report(name),
    }
}

/// Numbers that break readers which trust them: zero, negatives, the edges of the integer
/// types, beyond f32, and the non-finite spellings of TOML, JSON and XML writers.
pub const HOSTILE_NUMBERS: &[&str] = &[
    "0",
    "-1",
    "-0",
    "1e9",
    "1000000000",
    "4294967295",
    "4294967296",
    "2147483648",
    "-2147483649",
    "18446744073709551615",
    "99999999999999999999",
    "1e39",
    "-1e39",
    "1e-45",
    "3.5e38",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "Infinity",
    "0.0",
    "0.5",
    "65536",
    "16385",
];

/// 32-bit words written over binary headers: sizes and offsets at and around the edges.
pub const HOSTILE_WORDS: &[u32] =
    &[0, 1, 2, 0x7fff_ffff, 0x8000_0000, 0xffff_ffff, 0xffff_fffe, 0x0001_0000, 0x4000_0000, 0x00ff_ffff, 65537, 100_000];

/// One edit of a file. Positions are `Index`es, resolved against the length at the time the
/// edit applies; `head` edits land in the first KiB, where binary formats keep their headers.
#[derive(Clone, Debug)]
pub enum Mutation {
    FlipBit {
        at: Index,
        head: bool,
        bit: u8,
    },
    SetByte {
        at: Index,
        head: bool,
        value: u8,
    },
    Truncate {
        at: Index,
    },
    Delete {
        at: Index,
        len: u16,
    },
    /// Repeats a span (nesting, duplicated keys, repeated records).
    Duplicate {
        at: Index,
        len: u16,
    },
    /// Replaces the n-th run of ASCII digits (with sign, point, exponent) by a hostile number.
    Number {
        nth: Index,
        with: &'static str,
    },
    /// Inserts a hostile number at a position.
    InsertNumber {
        at: Index,
        with: &'static str,
    },
    /// Writes a little-endian 32- or 64-bit word.
    Word {
        at: Index,
        head: bool,
        value: u32,
        wide: bool,
    },
    /// Removes a whole line (a field, an element, a face).
    DeleteLine {
        nth: Index,
    },
}

impl Mutation {
    pub fn apply(&self, b: &mut Vec<u8>) {
        let pos = |at: &Index, head: bool, len: usize| if head { at.index(len.clamp(1, 1024)) } else { at.index(len.max(1)) };
        match self {
            Mutation::FlipBit { at, head, bit } => {
                if !b.is_empty() {
                    let i = pos(at, *head, b.len()).min(b.len() - 1);
                    b[i] ^= 1 << (bit % 8);
                }
            }
            Mutation::SetByte { at, head, value } => {
                if !b.is_empty() {
                    let i = pos(at, *head, b.len()).min(b.len() - 1);
                    b[i] = *value;
                }
            }
            Mutation::Truncate { at } => b.truncate(at.index(b.len() + 1)),
            Mutation::Delete { at, len } => {
                let i = at.index(b.len() + 1);
                let end = (i + *len as usize).min(b.len());
                b.drain(i..end);
            }
            Mutation::Duplicate { at, len } => {
                let i = at.index(b.len() + 1);
                let end = (i + *len as usize).min(b.len());
                let span = b[i..end].to_vec();
                b.splice(end..end, span);
            }
            Mutation::Number { nth, with } => {
                let runs = number_runs(b);
                if !runs.is_empty() {
                    let (s, e) = runs[nth.index(runs.len())];
                    b.splice(s..e, with.bytes());
                }
            }
            Mutation::InsertNumber { at, with } => {
                let i = at.index(b.len() + 1);
                b.splice(i..i, with.bytes());
            }
            Mutation::Word { at, head, value, wide } => {
                let bytes: Vec<u8> =
                    if *wide { (*value as u64 | ((*value as u64) << 32)).to_le_bytes().to_vec() } else { value.to_le_bytes().to_vec() };
                if b.len() >= bytes.len() {
                    let i = pos(at, *head, b.len() - bytes.len() + 1);
                    b[i..i + bytes.len()].copy_from_slice(&bytes);
                }
            }
            Mutation::DeleteLine { nth } => {
                let starts: Vec<usize> = std::iter::once(0)
                    .chain(b.iter().enumerate().filter(|(_, &c)| c == b'\n').map(|(i, _)| i + 1))
                    .filter(|&i| i < b.len())
                    .collect();
                if !starts.is_empty() {
                    let s = starts[nth.index(starts.len())];
                    let e = b[s..].iter().position(|&c| c == b'\n').map_or(b.len(), |p| s + p + 1);
                    b.drain(s..e);
                }
            }
        }
    }
}

/// Spans of numeric literals: a digit run with an optional leading '-', point and exponent.
fn number_runs(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() && (i == 0 || !b[i - 1].is_ascii_alphanumeric()) {
            let s = if i > 0 && b[i - 1] == b'-' { i - 1 } else { i };
            let mut e = i;
            while e < b.len()
                && (b[e].is_ascii_digit()
                    || b[e] == b'.'
                    || b[e] == b'e'
                    || b[e] == b'E'
                    || (b[e] == b'-' && e > 0 && matches!(b[e - 1], b'e' | b'E')))
            {
                e += 1;
            }
            out.push((s, e));
            i = e;
        } else {
            i += 1;
        }
    }
    out
}

pub fn mutation() -> impl Strategy<Value = Mutation> {
    let number = || prop::sample::select(HOSTILE_NUMBERS);
    prop_oneof![
        3 => (any::<Index>(), any::<bool>(), any::<u8>()).prop_map(|(at, head, bit)| Mutation::FlipBit { at, head, bit }),
        2 => (any::<Index>(), any::<bool>(), any::<u8>()).prop_map(|(at, head, value)| Mutation::SetByte { at, head, value }),
        1 => any::<Index>().prop_map(|at| Mutation::Truncate { at }),
        1 => (any::<Index>(), 1u16..64).prop_map(|(at, len)| Mutation::Delete { at, len }),
        1 => (any::<Index>(), 1u16..256).prop_map(|(at, len)| Mutation::Duplicate { at, len }),
        4 => (any::<Index>(), number()).prop_map(|(nth, with)| Mutation::Number { nth, with }),
        1 => (any::<Index>(), number()).prop_map(|(at, with)| Mutation::InsertNumber { at, with }),
        3 => (any::<Index>(), any::<bool>(), prop::sample::select(HOSTILE_WORDS), any::<bool>()).prop_map(|(at, head, value, wide)| Mutation::Word { at, head, value, wide }),
        2 => any::<Index>().prop_map(|nth| Mutation::DeleteLine { nth }),
    ]
}

/// One to four edits of one of `count` source files (by index). Half of the cases only replace
/// numbers: most other edits break the syntax, and those cases stop at the parser, while a file
/// that still parses with a hostile size or count in it reaches the checks and what they guard.
pub fn mutated(count: usize) -> impl Strategy<Value = (usize, Vec<Mutation>)> {
    let number = (any::<Index>(), prop::sample::select(HOSTILE_NUMBERS)).prop_map(|(nth, with)| Mutation::Number { nth, with });
    (0..count, prop_oneof![prop::collection::vec(mutation(), 1..=4), prop::collection::vec(number, 1..=3)])
}

pub fn apply_all(original: &[u8], edits: &[Mutation]) -> Vec<u8> {
    let mut b = original.to_vec();
    edits.iter().for_each(|m| m.apply(&mut b));
    b
}

/// Text assembled from a format's own tokens, so arbitrary inputs get past the lexer.
pub fn token_soup(tokens: &'static [&'static str], max: usize) -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(prop_oneof![4 => prop::sample::select(tokens), 1 => prop::sample::select(HOSTILE_NUMBERS)], 0..max)
        .prop_map(|t| t.concat().into_bytes())
}

pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// A fresh scratch directory for one test (tests of one binary run in parallel).
pub fn scratch(test: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz").join(test);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `path` as the case label: the file name and the edits.
pub fn label(source: &Path, edits: &[Mutation]) -> String {
    format!("{} with {edits:?}", source.display())
}
