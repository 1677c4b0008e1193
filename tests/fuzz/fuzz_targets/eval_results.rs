#![no_main]
//! Fuzz target: see `ssrdrive_fuzz_entries::eval_results`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ssrdrive_fuzz_entries::eval_results(data);
});
