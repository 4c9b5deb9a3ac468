//! Fuzz target: arbitrary bytes into the `.hyb` loader. Every input must come back as a
//! model or a rendered, located error; a panic, a hang or a stack overflow is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match std::str::from_utf8(data) {
        Ok(src) => {
            if let Err(e) = mvad::load::load_str("fuzz.hyb", src) {
                // Rendering is part of the contract: it must not panic either.
                let _ = e.to_string();
            }
        }
        Err(_) => {
            let _ = mvad::load::load_bytes("fuzz.hyb", data).map_err(|e| e.to_string());
        }
    }
});
