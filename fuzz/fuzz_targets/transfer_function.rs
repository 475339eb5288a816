//! A transfer-function JSON file (`--tf`): parsed, evaluated, and turned into the renderer's lookup table.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxstream_render::transfer_function::{TransferFunction, TransferLut};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(tf) = TransferFunction::from_json(text) else { return };
    for value in [-1.0, 0.0, 0.5, 1.0, 1e9, f64::NAN] {
        let _ = tf.evaluate(value);
    }
    let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
    let _ = lut.lookup(0.5);
    let _ = lut.is_visible_in(0.0, 1.0);
});
