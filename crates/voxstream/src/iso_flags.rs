//! The isosurface flags (`--iso`, `--iso-color`, `--iso-opacity`, `--shadows`) turned into the surfaces a frame
//! draws, with one clear error for each way they can be wrong.

use anyhow::{bail, Result};
use voxstream_render::{IsoSurface, MAX_SURFACES};

use crate::cli::{NormalsArg, RenderArgs};
use crate::render_command::shown_number;

/// Colours of the surfaces when `--iso-color` is not given, in order (linear RGB).
pub const PALETTE: [[f32; 3]; MAX_SURFACES] = [
    [0.9, 0.75, 0.65],
    [0.55, 0.7, 0.95],
    [0.95, 0.9, 0.5],
    [0.6, 0.9, 0.6],
    [0.95, 0.55, 0.55],
    [0.75, 0.6, 0.95],
    [0.5, 0.9, 0.9],
    [0.9, 0.9, 0.9],
];

/// Checks one isovalue against the data's `value_range`; `given` names where it came from (`--iso`, or a viewer
/// script's line and command), so `render --iso` and `view --script`'s `iso` refuse the same values alike.
pub fn check_isovalue(value: f64, value_range: [f64; 2], given: &str) -> Result<()> {
    let [lower, upper] = value_range;
    let value_text = shown_number(value);
    if !value.is_finite() {
        bail!("{given} {value_text} is not a finite number");
    }
    if value <= lower || value > upper {
        bail!(
            "{given} {value_text} lies outside the data's values ({lower} to {upper}): no surface can appear there; pick a \
             value between them (see `voxstream info`)"
        );
    }
    Ok(())
}

/// The surfaces the flags ask for (empty: volume rendering), checked against the data's `value_range`.
pub fn surfaces(args: &RenderArgs, value_range: [f64; 2]) -> Result<Vec<IsoSurface>> {
    if args.iso.is_empty() {
        if !args.iso_color.is_empty()
            || !args.iso_opacity.is_empty()
            || args.shadows
            || args.normals != NormalsArg::Cell
        {
            bail!("--iso-color, --iso-opacity, --shadows and --normals apply to isosurfaces: add --iso VALUE");
        }
        return Ok(Vec::new());
    }
    if args.iso.len() > MAX_SURFACES {
        bail!("--iso names {} values; at most {MAX_SURFACES} surfaces are drawn at once", args.iso.len());
    }
    for &value in &args.iso {
        check_isovalue(value, value_range, "--iso")?;
    }
    let colors = match args.iso_color.len() {
        0 => PALETTE[..args.iso.len()].to_vec(),
        n if n != args.iso.len() => {
            bail!("--iso-color gives {n} colours for {} isovalues: give one per value", args.iso.len())
        }
        _ => args.iso_color.iter().map(|c| c.map(|v| v as f32)).collect(),
    };
    let opacities = match args.iso_opacity.len() {
        0 => vec![1.0; args.iso.len()],
        n if n != args.iso.len() => {
            bail!("--iso-opacity gives {n} opacities for {} isovalues: give one per value", args.iso.len())
        }
        _ => args.iso_opacity.clone(),
    };
    if let Some(bad) = opacities.iter().find(|a| !(**a > 0.0 && **a <= 1.0)) {
        bail!("--iso-opacity {bad} is not in (0, 1]");
    }
    if args.shadows && args.light.is_none() {
        bail!("--shadows needs a light that is not at the eye: add --light x,y,z (the direction towards the light)");
    }
    Ok(args
        .iso
        .iter()
        .zip(colors)
        .zip(opacities)
        .map(|((&value, color), opacity)| IsoSurface { value, color, opacity })
        .collect())
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
