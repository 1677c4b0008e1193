#![no_main]
//! Fuzz target: see `ssrdrive_fuzz_entries::image_decode`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ssrdrive_fuzz_entries::image_decode(data);
});
