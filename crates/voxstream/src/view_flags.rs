//! The flags `render` and `view` share ([`SourceFlags`], [`LookFlags`]) as the facade's typed options: one
//! translation for both commands, so the same flag means the same thing and fails with the same message in each.

use voxstream_api::camera_presets::CameraTurn;
use voxstream_api::{CameraOptions, IsoOptions, SessionOptions, SourceOptions, TransferFunctionChoice, ViewOptions};
use voxstream_render::Shading;

use crate::cli::{LookFlags, NormalsArg, ShadingArg, SourceFlags, Switch};

/// How to open SOURCE, for images of `width × height`; `quiet` hides the value-range scan's progress bar.
pub fn source_options(flags: &SourceFlags, width: u32, height: u32, quiet: bool) -> SourceOptions {
    SourceOptions {
        value_range: flags.value_range,
        in_memory: flags.in_memory,
        brick_bits: flags.brick_bits,
        amplify: flags.amplify,
        resolution: flags.resolution,
        attribute: flags.attribute,
        smoothing_scale: flags.smoothing_scale,
        particle_memory: flags.particle_memory,
        planes: voxstream_store::image_planes::PlaneChoice { channel: flags.channel, time: flags.time },
        remote: flags.remote.access(),
        width,
        height,
        quiet,
    }
}

/// The view the flags ask for, `width × height` pixels.
pub fn view_options(look: &LookFlags, width: u32, height: u32) -> ViewOptions {
    ViewOptions {
        width,
        height,
        transfer_function: match &look.tf {
            Some(path) => TransferFunctionChoice::File(path.clone()),
            None => TransferFunctionChoice::Default,
        },
        iso: IsoOptions {
            values: look.iso.clone(),
            colors: look.iso_color.clone(),
            opacities: look.iso_opacity.clone(),
            shadows: look.shadows,
            central_normals: look.normals == NormalsArg::Central,
        },
        shading: look.shading.map(|shading| match shading {
            ShadingArg::None => Shading::None,
            ShadingArg::Phong => Shading::Phong,
        }),
        light: look.light,
        background: look.background,
        step: look.step,
        preintegrate: look.preintegrate,
        adaptive_step: look.adaptive_step,
        faithful: look.faithful,
        lod_bias: look.lod_bias,
        colour_by_level: look.colour_by_level,
        camera: CameraOptions {
            file: look.camera.clone(),
            camera: None,
            eye: look.eye,
            target: look.target,
            up: look.up,
            fov: look.fov,
            preset: look.view,
            turn: CameraTurn { azimuth: look.azimuth, elevation: look.elevation, zoom: look.zoom },
        },
        region: look.crop,
        projection: look.projection.projection(),
        clip_planes: look.clip_plane.clone(),
        slice: look.slice.map(|slice| voxstream_api::slices::Slice { with_volume: look.with_volume, ..slice }),
        volume_slice: None,
    }
}

/// The session the flags ask for, within `budget_mb`, serving `requests_per_frame` per interactive frame.
pub fn session_options(look: &LookFlags, budget_mb: u64, requests_per_frame: usize) -> SessionOptions {
    SessionOptions {
        budget_mb,
        backend: look.backend,
        gpu_filter: look.gpu_filter,
        requests_per_frame,
        blending: look.blending == Switch::On,
        fade_frames: look.fade_frames,
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;
    use crate::cli::{Cli, Command};

    fn parse(command: &str, flags: &[&str]) -> Command {
        let args = ["voxstream", command].into_iter().chain(flags.iter().copied());
        Cli::try_parse_from(args).expect("the flags parse").command.expect("a command")
    }

    #[test]
    fn render_and_view_read_the_shared_flags_alike() {
        let flags = [
            "shell",
            "--eye",
            "1,2,3",
            "--fov",
            "40",
            "--iso",
            "0.3,0.6",
            "--iso-color",
            "1,0,0;0,1,0",
            "--shadows",
            "--light",
            "0,0,1",
            "--tf",
            "x.json",
            "--lod-bias",
            "0.5",
            "--blending",
            "off",
            "--normals",
            "central",
            "--background",
            "0.1,0.2,0.3",
            "--in-memory",
            "--value-range",
            "0,10",
            "--backend",
            "gpu",
        ];
        let (Command::Render(render), Command::View(view)) = (parse("render", &flags), parse("view", &flags)) else {
            panic!("render and view");
        };
        let render_view = view_options(&render.look, 300, 200);
        assert_eq!(format!("{render_view:?}"), format!("{:?}", view_options(&view.look, 300, 200)));
        assert_eq!(render_view.camera.eye, Some([1.0, 2.0, 3.0]));
        assert_eq!(render_view.iso.colors, vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert!(render_view.iso.central_normals && render_view.iso.shadows);
        let source = |flags: &SourceFlags| format!("{:?}", source_options(flags, 300, 200, true));
        assert_eq!(source(&render.input), source(&view.input));
        assert_eq!(render.input.source, "shell");
        assert_eq!(session_options(&render.look, 64, 8), session_options(&view.look, 64, 8));
        assert!(!session_options(&view.look, 64, 8).blending);
    }
}
