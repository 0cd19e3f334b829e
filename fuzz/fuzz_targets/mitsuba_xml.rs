//! Fuzzes the Mitsuba XML loader: any text must give a scene or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = pathgrad::scene::mitsuba::load_str(text, std::path::Path::new("/nonexistent/fuzz.xml"), &[]);
    }
});
