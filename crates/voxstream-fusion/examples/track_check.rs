//! Frame-to-frame ICP on a synthetic orbit: each frame tracked against the previous frame's own depth (exact or
//! noisy), from the previous true pose; prints the error of each estimate. Separates the tracker's accuracy from the
//! fused model's: `cargo run --release -p voxstream-fusion --example track_check -- MESH [FRAMES] [noise] [walls]`.

use voxstream_fusion::rgbd::{NoiseModel, SyntheticSequence, SyntheticSettings};
use voxstream_fusion::tracking::{prepare_frame, track, ModelView, TrackingSettings};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let frames: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(300);
    let noise = args.get(3).is_some_and(|a| a == "noise");
    let walls: f64 = args.get(4).and_then(|a| a.parse().ok()).unwrap_or(0.0);
    let settings = SyntheticSettings {
        frames,
        walls,
        noise: if noise { NoiseModel::KINECT_V1 } else { NoiseModel::NONE },
        world: SyntheticSettings::tilted_world(),
        ..SyntheticSettings::default()
    };
    let sequence = SyntheticSequence::from_mesh_file(std::path::Path::new(&args[1]), settings).expect("mesh");
    let k = sequence.settings().intrinsics;
    let mut errors = Vec::new();
    for i in 1..sequence.len().min(40) {
        let previous = sequence.frame(i - 1);
        let frame = sequence.frame(i);
        let model = ModelView::from_depth(&prepare_frame(&previous.depth, &k), k, sequence.pose(i - 1));
        let truth = sequence.pose(i);
        let depth =
            if std::env::var_os("RAW").is_some() { frame.depth.clone() } else { prepare_frame(&frame.depth, &k) };
        match track(&depth, &k, &model, sequence.pose(i - 1), &TrackingSettings::default()) {
            Ok(r) => {
                let moved = (truth.translation - sequence.pose(i - 1).translation).length();
                let error = (r.pose.translation - truth.translation).length();
                errors.push(error);
                println!(
                    "frame {i}: moved {:.1} mm, error {:.2} mm, rms {:.2} mm, {} iterations",
                    moved * 1e3,
                    error * 1e3,
                    r.rms_residual * 1e3,
                    r.iterations
                );
            }
            Err(e) => println!("frame {i}: {e}"),
        }
    }
    println!("mean error {:.2} mm", errors.iter().sum::<f64>() / errors.len() as f64 * 1e3);
}
