#![no_main]
//! Fuzz target: see `ssrdrive_fuzz_entries::map_xodr`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ssrdrive_fuzz_entries::map_xodr(data);
});
