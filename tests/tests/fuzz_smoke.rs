//! The fuzz targets' smoke run without AFL (issue #15 item 2): every file of
//! `fuzz/corpus/<target>/` and `fuzz/regressions/<target>/`, and a deterministic set of simple
//! mutations of each corpus file (truncations, byte flips, numbers replaced by huge or odd ones,
//! huge numbers inserted, chunks cut or repeated), through the same harness functions the AFL
//! targets call. Passes when no reader panics.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use trisplat_tests::fuzz_harness::{Target, remove_work_dir};

/// Numbers put where the file had one, or inserted anywhere.
const ODD_NUMBERS: [&[u8]; 10] = [
    b"0",
    b"-1",
    b"255",
    b"65536",
    b"4294967295",
    b"18446744073709551616",
    b"99999999999999999999999999",
    b"1e309",
    b"NaN",
    b"-0.0",
];

/// The files of `fuzz/<kind>/<target>/`, sorted (none when the folder is missing).
fn files(kind: &str, target: Target) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz")
        .join(kind)
        .join(target.name());
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
}

/// Inputs per target at least (a target with few seeds gets stacked mutations).
const MIN_INPUTS_PER_TARGET: usize = 3000;

/// splitmix64: a small seeded generator, so the mutations are the same on every run.
struct Mix(u64);

impl Mix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A position in `0..len` (`len > 0`); half of them in the first KiB, where headers are.
    fn position(&mut self, len: usize) -> usize {
        let span = if self.next().is_multiple_of(2) {
            len.min(1024)
        } else {
            len
        };
        (self.next() % span as u64) as usize
    }
}

/// The deterministic mutations of one seed (the seed itself first).
fn mutations(seed: &[u8], rng_seed: u64) -> Vec<Vec<u8>> {
    let mut out = vec![seed.to_vec()];
    let len = seed.len();
    if len == 0 {
        return out;
    }
    let mut rng = Mix(rng_seed);
    // Truncations.
    for k in 0..32 {
        out.push(seed[..len * k / 32].to_vec());
    }
    out.push(seed[..len - 1].to_vec());
    // Byte flips.
    for _ in 0..200 {
        let mut m = seed.to_vec();
        let at = rng.position(len);
        m[at] = match rng.next() % 4 {
            0 => m[at] ^ 0xFF,
            1 => m[at] ^ (1 << (rng.next() % 8)),
            2 => 0,
            _ => rng.next() as u8,
        };
        out.push(m);
    }
    // Each of the first numbers (in the first 8 KiB) replaced by every odd number.
    let head = &seed[..len.min(8192)];
    let mut runs = Vec::new();
    let mut i = 0;
    while i < head.len() && runs.len() < 48 {
        if head[i].is_ascii_digit() {
            let start = i;
            while i < head.len() && (head[i].is_ascii_digit() || head[i] == b'.') {
                i += 1;
            }
            runs.push(start..i);
        } else {
            i += 1;
        }
    }
    for run in &runs {
        for number in ODD_NUMBERS {
            let mut m = seed[..run.start].to_vec();
            m.extend_from_slice(number);
            m.extend_from_slice(&seed[run.end..]);
            out.push(m);
        }
    }
    // Odd numbers inserted anywhere.
    for _ in 0..60 {
        let at = rng.position(len);
        let number = ODD_NUMBERS[(rng.next() % ODD_NUMBERS.len() as u64) as usize];
        let mut m = seed[..at].to_vec();
        m.extend_from_slice(number);
        m.extend_from_slice(&seed[at..]);
        out.push(m);
    }
    // Chunks cut out or repeated.
    for _ in 0..40 {
        let a = rng.position(len);
        let b = (a + 1 + (rng.next() % 64) as usize).min(len);
        let mut m = seed[..a].to_vec();
        if rng.next().is_multiple_of(2) {
            m.extend_from_slice(&seed[a..b]);
            m.extend_from_slice(&seed[a..b]);
        }
        m.extend_from_slice(&seed[b..]);
        out.push(m);
    }
    out
}

/// Runs `target` on `input`; the panic message when it panics.
fn run(target: Target, input: &[u8]) -> Result<bool, String> {
    catch_unwind(AssertUnwindSafe(|| target.run(input))).map_err(|payload| {
        payload
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| payload.downcast_ref::<&str>().map(|s| (*s).to_string()))
            .unwrap_or_else(|| "non-string panic".to_string())
    })
}

#[test]
fn every_reader_survives_its_corpus_mutations_and_regressions() {
    let mut failures = Vec::new();
    for target in Target::ALL {
        let corpus = files("corpus", target);
        assert!(
            !corpus.is_empty(),
            "fuzz/corpus/{} has no seed files",
            target.name()
        );
        let (mut inputs, mut accepted) = (0usize, 0usize);
        // Targets with few seeds get mutations of mutations, up to their share of the total.
        let quota = MIN_INPUTS_PER_TARGET.div_ceil(corpus.len());
        for (s, file) in corpus.iter().enumerate() {
            let seed = std::fs::read(file).expect("read corpus file");
            let first = mutations(&seed, s as u64 + 1);
            let mut count = 0;
            let mut check = |what: String, input: &[u8]| match run(target, input) {
                Ok(ok) => accepted += usize::from(ok),
                Err(message) => failures.push(format!(
                    "{}: {} {what}: {message}",
                    target.name(),
                    file.display()
                )),
            };
            for (m, input) in first.iter().enumerate() {
                check(format!("mutation {m}"), input);
                count += 1;
            }
            let mut round = 0;
            while count < quota {
                let base = round % first.len();
                let rng_seed = (s as u64 + 1) * 1_000_003 + round as u64;
                for (m, input) in mutations(&first[base], rng_seed).iter().enumerate().skip(1) {
                    if count >= quota {
                        break;
                    }
                    check(format!("mutation {base} then {m} (seed {rng_seed})"), input);
                    count += 1;
                }
                round += 1;
            }
            inputs += count;
        }
        for file in files("regressions", target) {
            inputs += 1;
            let input = std::fs::read(&file).expect("read regression file");
            if let Err(message) = run(target, &input) {
                failures.push(format!("{}: {}: {message}", target.name(), file.display()));
            }
        }
        // The corpus must reach the readers' success paths too, not only their first check.
        assert!(accepted > 0, "{}: no input accepted", target.name());
        eprintln!("{}: {inputs} inputs, {accepted} accepted", target.name());
    }
    remove_work_dir();
    assert!(failures.is_empty(), "panics:\n{}", failures.join("\n"));
}
