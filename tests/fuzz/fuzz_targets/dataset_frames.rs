#![no_main]
//! Fuzz target: see `ssrdrive_fuzz_entries::dataset_frames`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ssrdrive_fuzz_entries::dataset_frames(data);
});
