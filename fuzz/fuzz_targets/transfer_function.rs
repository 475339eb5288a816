//! A transfer-function JSON file (`--tf`: voxstream's format or a ParaView colour-map preset): parsed, evaluated, and
//! turned into the renderer's lookup tables.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxstream_render::step_table::StepLength;
use voxstream_render::transfer_function::{TransferFunction, TransferLut};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(tf) = TransferFunction::from_json_or_paraview(text, [-3.0, 1e6]) else { return };
    for value in [-1.0, 0.0, 0.5, 1.0, 1e9, f64::NAN] {
        let _ = tf.evaluate(value);
    }
    let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
    let _ = lut.lookup(0.5);
    let _ = lut.is_visible_in(0.0, 1.0);
    // The tables pre-corrected for a step: any extinction, tiny and huge steps.
    for step in [1e-9, 0.37, 1e9] {
        let _ = lut.step_table(StepLength::at_most(step)).lookup(0.5);
    }
});
