//! Replays every fuzz seed (`tests/fuzz/seeds/<target>/`) and every input the fuzzers found to crash,
//! hang or exhaust memory (`tests/fuzz/regressions/<target>/`, each fixed since) through the same
//! entry the fuzzer uses: every seed must be accepted (or, named `refused-*`, refused), every
//! regression input handled without a crash. CI runs this; it does not fuzz.

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
                let accepted = entry(&std::fs::read(&path).unwrap());
                // A seed gets past the parser's checks, except one named `refused-*` (a
                // checkpoint the fuzzer's input size can hold stops before the end); a
                // regression input need only not crash.
                let name = path.file_name().unwrap().to_string_lossy();
                if folder == "seeds" {
                    assert_eq!(
                        accepted,
                        !name.starts_with("refused-"),
                        "{target}: the seed {name} is {}",
                        if accepted { "accepted" } else { "refused" }
                    );
                }
                replayed += 1;
                seeds += usize::from(folder == "seeds");
            }
        }
        assert!(seeds > 0, "no seeds for {target}");
    }
    eprintln!("{replayed} inputs replayed");
}
