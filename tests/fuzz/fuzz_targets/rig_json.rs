#![no_main]
//! Fuzz target: see `ssrdrive_fuzz_entries::rig_json`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ssrdrive_fuzz_entries::rig_json(data);
});
