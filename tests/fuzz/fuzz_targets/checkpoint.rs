#![no_main]
//! Fuzz target: see `ssrdrive_fuzz_entries::checkpoint`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ssrdrive_fuzz_entries::checkpoint(data);
});
