//! Scripted sessions (`voxstream view --script FILE`): camera moves and UI actions, one per line, run in the window
//! as a user would do them, for reproducible demonstrations and for end-to-end tests.
//!
//! ```text
//! # comments and blank lines are ignored
//! wait-final 120          # wait until the image is final: full resolution, nothing missing (timeout, seconds)
//! screenshot before.png   # the image as shown, at the render size (PNG)
//! orbit 30 -10            # degrees about the up axis, and towards it
//! pan 0.1 0               # across the view, in image heights
//! zoom 0.8                # eye distance × 0.8
//! fly 0.05 0 0            # forward, right, up (world units)
//! reset                   # the starting view
//! tf-point 0.5 1 0 0 0.3  # add (or move) a transfer-function point: value r g b opacity
//! tf-delete 1             # delete point 1
//! load-tf tf.json         # a transfer function file (`render --tf`'s format, or a ParaView colour map)
//! save-tf tf.json         # the edited transfer function, for `voxstream render --tf`
//! save-camera camera.json # the camera, for `voxstream render --camera`
//! shading phong           # or none
//! lod-bias 1              # coarser (positive) or finer (negative) level of detail
//! overlay on              # mark the pixels still missing data
//! levels on              # colour the volume by the tree level each sample's data came from
//! iso 1500                # an exact isosurface at this data value instead of the volume (`iso off`: the volume)
//! iso-volume on           # with the isosurface: the volume drawn around it too (`off`: the surface alone)
//! wait 0.5                # seconds
//! quit                    # close the window
//! ```
//!
//! The whole file is checked before the window opens: an error names the line and the fix.

use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::error::ViewerError;

/// The largest pool budget the window and scripts accept, MiB (1 TiB, `render --budget-mb`'s bound).
pub const MAX_BUDGET_MIB: u64 = 1 << 20;

/// Default timeout of `wait-final`.
pub const DEFAULT_WAIT_FINAL: Duration = Duration::from_secs(120);

/// The commands, with what each takes.
const COMMANDS: &str = "wait-final [SECONDS], wait SECONDS, screenshot PNG, window-screenshot PNG, orbit YAW PITCH, pan RIGHT UP, zoom FACTOR, \
                        fly FORWARD RIGHT UP, reset, tf-point VALUE R G B OPACITY, tf-delete INDEX, load-tf FILE, \
                        save-tf FILE, save-camera FILE, shading phong|none, lod-bias BIAS, overlay on|off, levels on|off, iso VALUE|off, iso-volume on|off, \
                        budget MIB, quit";

/// One scripted action.
#[derive(Clone, Debug, PartialEq)]
pub enum ScriptCommand {
    /// Wait until the shown image is final for the current view.
    WaitFinal(Duration),
    /// Wait this long.
    Wait(Duration),
    /// Save the shown image.
    Screenshot(PathBuf),
    /// Orbit by yaw and pitch, degrees.
    Orbit(f64, f64),
    /// Pan by fractions of the image height.
    Pan(f64, f64),
    /// Multiply the eye's distance.
    Zoom(f64),
    /// Move forward, right and up.
    Fly(f64, f64, f64),
    /// Back to the starting view.
    Reset,
    /// Add or move a transfer-function point.
    TfPoint([f64; 5]),
    /// Delete a transfer-function point.
    TfDelete(usize),
    /// Load a transfer function.
    LoadTf(PathBuf),
    /// Save the transfer function.
    SaveTf(PathBuf),
    /// Save the camera.
    SaveCamera(PathBuf),
    /// Phong shading on or off.
    Phong(bool),
    /// Level-of-detail bias.
    LodBias(f64),
    /// The missing-data overlay on or off.
    Overlay(bool),
    /// Colour by the level used, on or off.
    Levels(bool),
    /// An isosurface at this value instead of the volume, or the volume again.
    Iso(Option<f64>),
    /// With an isosurface: the volume drawn around it too (`render --iso … --tf …`), or the surface alone.
    IsoInVolume(bool),
    /// The pools' budget, MiB (as the window's budget field).
    Budget(u64),
    /// Save the whole window (image, panels, status line) as it is drawn.
    WindowScreenshot(PathBuf),
    /// Close the window.
    Quit,
}

/// A parsed script: its commands with their line numbers.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Script {
    /// `(line number from 1, command)`.
    pub commands: Vec<(usize, ScriptCommand)>,
    /// The file it came from (for messages).
    pub name: String,
}

/// Largest script file read (bytes): a script is a few lines; anything larger is not one.
const MAX_SCRIPT_BYTES: u64 = 1 << 20;

impl Script {
    /// Reads and checks a script file.
    pub fn read(path: &Path) -> Result<Script, ViewerError> {
        let fail = |message: String| ViewerError::Script(format!("{}: {message}", path.display()));
        let size = std::fs::metadata(path).map_err(|e| fail(format!("cannot read the script: {e}")))?.len();
        if size > MAX_SCRIPT_BYTES {
            return Err(fail(format!("{size} bytes is not a script (at most {MAX_SCRIPT_BYTES} bytes)")));
        }
        let text = std::fs::read_to_string(path).map_err(|e| fail(format!("cannot read the script: {e}")))?;
        Script::parse(&text, &path.display().to_string())
    }

    /// Parses a script's text; `name` names it in messages.
    pub fn parse(text: &str, name: &str) -> Result<Script, ViewerError> {
        let mut commands = Vec::new();
        for (index, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let command = parse_line(line)
                .map_err(|message| ViewerError::Script(format!("{name} line {}: {message}", index + 1)))?;
            commands.push((index + 1, command));
        }
        Ok(Script { commands, name: name.to_string() })
    }
}

fn parse_line(line: &str) -> Result<ScriptCommand, String> {
    let mut words = line.split_whitespace();
    let verb = words.next().unwrap_or("");
    let rest: Vec<&str> = words.collect();
    let numbers = |count: usize| -> Result<Vec<f64>, String> {
        if rest.len() != count {
            return Err(format!("`{verb}` takes {count} number(s), got {}", rest.len()));
        }
        rest.iter()
            .map(|w| w.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("`{w}` is not a number")))
            .collect()
    };
    let path = || -> Result<PathBuf, String> {
        match rest.as_slice() {
            [one] => Ok(PathBuf::from(one)),
            _ => Err(format!("`{verb}` takes one file name (without spaces)")),
        }
    };
    let switch = |on: &str, off: &str| -> Result<bool, String> {
        match rest.as_slice() {
            [w] if *w == on => Ok(true),
            [w] if *w == off => Ok(false),
            _ => Err(format!("`{verb}` takes `{on}` or `{off}`")),
        }
    };
    let seconds = |value: f64| -> Result<Duration, String> {
        Duration::try_from_secs_f64(value).map_err(|_| format!("{value} is not a number of seconds"))
    };
    Ok(match verb {
        "wait-final" => match rest.len() {
            0 => ScriptCommand::WaitFinal(DEFAULT_WAIT_FINAL),
            _ => ScriptCommand::WaitFinal(seconds(numbers(1)?[0])?),
        },
        "wait" => ScriptCommand::Wait(seconds(numbers(1)?[0])?),
        "screenshot" => ScriptCommand::Screenshot(path()?),
        "window-screenshot" => ScriptCommand::WindowScreenshot(path()?),
        "orbit" => {
            let v = numbers(2)?;
            ScriptCommand::Orbit(v[0], v[1])
        }
        "pan" => {
            let v = numbers(2)?;
            ScriptCommand::Pan(v[0], v[1])
        }
        "zoom" => {
            let v = numbers(1)?[0];
            if v <= 0.0 {
                return Err(format!("zoom factor must be positive, got {v}"));
            }
            ScriptCommand::Zoom(v)
        }
        "fly" => {
            let v = numbers(3)?;
            ScriptCommand::Fly(v[0], v[1], v[2])
        }
        "reset" if rest.is_empty() => ScriptCommand::Reset,
        "tf-point" => {
            let v = numbers(5)?;
            if v[1..].iter().any(|c| !(0.0..=1.0).contains(c)) {
                return Err("r, g, b and opacity must be in [0, 1]".into());
            }
            ScriptCommand::TfPoint([v[0], v[1], v[2], v[3], v[4]])
        }
        "tf-delete" => match rest.as_slice() {
            [w] => ScriptCommand::TfDelete(w.parse().map_err(|_| format!("`{w}` is not a point index"))?),
            _ => return Err("`tf-delete` takes one point index".into()),
        },
        "load-tf" => ScriptCommand::LoadTf(path()?),
        "save-tf" => ScriptCommand::SaveTf(path()?),
        "save-camera" => ScriptCommand::SaveCamera(path()?),
        "shading" => ScriptCommand::Phong(switch("phong", "none")?),
        "lod-bias" => ScriptCommand::LodBias(numbers(1)?[0]),
        "overlay" => ScriptCommand::Overlay(switch("on", "off")?),
        "levels" => ScriptCommand::Levels(switch("on", "off")?),
        "iso" => match rest.as_slice() {
            ["off"] => ScriptCommand::Iso(None),
            _ => ScriptCommand::Iso(Some(numbers(1).map_err(|_| "`iso` takes a data value or `off`".to_string())?[0])),
        },
        "iso-volume" => ScriptCommand::IsoInVolume(switch("on", "off")?),
        "budget" => match rest.as_slice() {
            [w] => match w.parse::<u64>() {
                Ok(mib) if (1..=MAX_BUDGET_MIB).contains(&mib) => ScriptCommand::Budget(mib),
                _ => return Err(format!("`budget` takes MiB from 1 to {MAX_BUDGET_MIB}, got `{w}`")),
            },
            _ => return Err("`budget` takes one number of MiB".into()),
        },
        "quit" if rest.is_empty() => ScriptCommand::Quit,
        "reset" | "quit" => return Err(format!("`{verb}` takes nothing")),
        other => return Err(format!("unknown command `{other}` (expected one of: {COMMANDS})")),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_script_parses_with_line_numbers_and_comments() {
        let script = Script::parse(
            "# a test\nwait-final 30\norbit 30 -10  # turn\n\nscreenshot a.png\ntf-point 0.5 1 0 0 0.3\nquit\n",
            "s",
        )
        .unwrap();
        assert_eq!(
            script.commands,
            vec![
                (2, ScriptCommand::WaitFinal(Duration::from_secs(30))),
                (3, ScriptCommand::Orbit(30.0, -10.0)),
                (5, ScriptCommand::Screenshot("a.png".into())),
                (6, ScriptCommand::TfPoint([0.5, 1.0, 0.0, 0.0, 0.3])),
                (7, ScriptCommand::Quit),
            ]
        );
    }

    #[test]
    fn errors_name_the_line_and_what_was_expected() {
        let message = |text: &str| Script::parse(text, "s.txt").unwrap_err().to_string();
        assert!(message("wait-final\norbt 3 4").contains("s.txt line 2: unknown command `orbt`"));
        assert!(message("orbit 3").contains("line 1: `orbit` takes 2 number(s), got 1"));
        assert!(message("zoom -2").contains("zoom factor must be positive"));
        assert!(message("orbit nan 1").contains("`nan` is not a number"));
        assert!(message("tf-point 0 2 0 0 0").contains("in [0, 1]"));
        assert!(message("wait 1e300").contains("not a number of seconds"));
        assert!(message("shading flat").contains("`shading` takes `phong` or `none`"));
        assert!(message("budget 0").contains("`budget` takes MiB from 1 to 1048576, got `0`"));
        assert!(message("budget 2e6").contains("got `2e6`"));
        assert_eq!(Script::parse("budget 48", "s").unwrap().commands, vec![(1, ScriptCommand::Budget(48))]);
        assert!(message("quit now").contains("`quit` takes nothing"));
        assert!(message("iso x").contains("`iso` takes a data value or `off`"));
        assert_eq!(Script::parse("iso off\niso 2.5", "s").unwrap().commands[1].1, ScriptCommand::Iso(Some(2.5)));
    }
}

#[cfg(test)]
mod properties {
    use proptest::prelude::*;

    use super::*;

    proptest! {
        /// Any text parses or fails with a message naming a line: never a panic.
        #[test]
        fn any_text_parses_or_names_a_line(text in "(?s).{0,400}") {
            if let Err(error) = Script::parse(&text, "s") {
                prop_assert!(error.to_string().starts_with("s line "));
            }
        }

        /// Lines of known words with arbitrary arguments, likewise.
        #[test]
        fn command_words_with_any_arguments(lines in proptest::collection::vec(
            ("(wait-final|wait|screenshot|orbit|pan|zoom|fly|reset|tf-point|tf-delete|load-tf|save-tf|save-camera|shading|lod-bias|overlay|levels|iso|iso-volume|quit)",
             proptest::collection::vec("[-+0-9.eEnaifNA ]{0,8}|on|off|phong|none|x.png", 0..6)), 0..12)) {
            let text: String = lines.iter().map(|(verb, args)| format!("{verb} {}\n", args.join(" "))).collect();
            if let Err(error) = Script::parse(&text, "s") {
                prop_assert!(error.to_string().starts_with("s line "));
            }
        }
    }
}
