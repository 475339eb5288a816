//! The isosurface flags (`--iso`, `--iso-color`, `--iso-opacity`, `--shadows`) turned into the surfaces a frame
//! draws, with one clear error for each way they can be wrong.

use anyhow::Result;
use voxstream_render::IsoSurface;

use crate::cli::RenderArgs;

pub use voxstream_api::view::{check_isovalue, PALETTE};

/// The surfaces the flags ask for (empty: volume rendering), checked against the data's `value_range`.
pub fn surfaces(args: &RenderArgs, value_range: [f64; 2]) -> Result<Vec<IsoSurface>> {
    voxstream_api::view::surfaces(&crate::render_command::view_options(args).iso, args.look.light, value_range)
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;
    use crate::cli::{Cli, Command};

    fn args(flags: &[&str]) -> RenderArgs {
        let cli = Cli::try_parse_from(["voxstream", "render", "store"].iter().chain(flags)).expect("flags parse");
        match cli.command {
            Some(Command::Render(args)) => args,
            _ => unreachable!("a render command"),
        }
    }

    fn error(flags: &[&str]) -> String {
        surfaces(&args(flags), [0.0, 255.0]).expect_err("refused").to_string()
    }

    #[test]
    fn values_colours_and_opacities_pair_up() {
        let s = surfaces(&args(&["--iso", "40,110", "--iso-opacity", "0.3,1"]), [0.0, 255.0]).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!((s[0].value, s[0].color, s[0].opacity), (40.0, PALETTE[0], 0.3));
        assert_eq!((s[1].value, s[1].opacity), (110.0, 1.0));
        let s = surfaces(&args(&["--iso", "70", "--iso-color", "1,0,0"]), [0.0, 255.0]).unwrap();
        assert_eq!(s[0].color, [1.0, 0.0, 0.0]);
        assert!(surfaces(&args(&[]), [0.0, 255.0]).unwrap().is_empty());
    }

    #[test]
    fn each_mistake_gets_its_own_message() {
        assert!(error(&["--iso", "300"]).contains("outside the data's values (0 to 255)"));
        assert!(error(&["--iso", "0"]).contains("outside"), "the minimum itself bounds nothing");
        assert!(error(&["--iso", "1,2", "--iso-color", "1,0,0"]).contains("1 colours for 2 isovalues"));
        let two = surfaces(&args(&["--iso", "1,2", "--iso-color", "1,0,0;0,0,1"]), [0.0, 255.0]).unwrap();
        assert_eq!(two[1].color, [0.0, 0.0, 1.0]);
        let repeated = surfaces(&args(&["--iso", "1,2", "--iso-color", "1,0,0", "--iso-color", "0,0,1"]), [0.0, 255.0]);
        assert_eq!(repeated.unwrap(), two);
        assert!(error(&["--iso", "1,2", "--iso-opacity", "1"]).contains("1 opacities for 2 isovalues"));
        assert!(error(&["--iso", "1", "--iso-opacity", "0"]).contains("not in (0, 1]"));
        assert!(error(&["--iso", "1", "--shadows"]).contains("--light"));
        assert_eq!(surfaces(&args(&["--iso", "1", "--tf", "x.json"]), [0.0, 255.0]).unwrap().len(), 1);
        assert!(error(&["--shadows"]).contains("add --iso"));
        assert!(error(&["--normals", "central"]).contains("add --iso"));
        assert!(error(&["--iso", "1,2,3,4,5,6,7,8,9"]).contains("at most 8"));
    }
}
