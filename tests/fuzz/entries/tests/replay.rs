//! Replays every fuzz seed (`tests/fuzz/seeds/<target>/`) and every input the fuzzers found to crash,
//! hang or exhaust memory (`tests/fuzz/regressions/<target>/`, each fixed since) through the same
//! entry the fuzzer uses. CI runs this; it does not fuzz.

use std::path::Path;

use ssrdrive_fuzz_entries::TARGETS;

#[test]
fn every_seed_and_regression_input_is_handled() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut replayed = 0;
    for (target, entry) in TARGETS {
        let mut seeds = 0;
        for folder in ["seeds", "regressions"] {
            let dir = root.join(folder).join(target);
            let Ok(files) = std::fs::read_dir(&dir) else {
                continue;
            };
            for file in files {
                let path = file.unwrap().path();
                eprintln!("{target}: {}", path.display());
                entry(&std::fs::read(&path).unwrap());
                replayed += 1;
                seeds += usize::from(folder == "seeds");
            }
        }
        assert!(seeds > 0, "no seeds for {target}");
    }
    eprintln!("{replayed} inputs replayed");
}
