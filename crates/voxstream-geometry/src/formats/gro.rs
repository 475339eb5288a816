//! GROMACS coordinate files (`.gro`, <https://manual.gromacs.org/current/reference-manual/file-formats.html#gro>):
//! atoms as particles, positions in the file's nm, each atom's van der Waals radius (nm) as its smoothing length.
//!
//! The file is a title line, the atom count, one fixed-column line per atom (residue number and name, atom name and
//! number in 5 columns each, then x, y, z) and the box line. The coordinates' width is found as GROMACS finds it,
//! from the distance between the first two decimal points of the first atom line (`%8.3f` normally, wider for more
//! decimals), and then holds for every atom line. The element is the atom name's first letter, or the ion the
//! residue is named after ([`super::elements`]); its Bondi radius goes into `smoothing`. Masses and values are left
//! empty.
//!
//! Not read: velocities and the box (checked for numbers, not kept); frames after the first of a trajectory.

use std::path::Path;

use super::elements::{element_from_atom_name, vdw_radius_angstrom};
use crate::error::GeometryError;
use crate::particles::RawParticles;

/// The shortest atom line: 20 columns of names and numbers, three coordinates of at least 6 characters, a newline.
const MIN_ATOM_LINE_BYTES: usize = 20 + 3 * 6 + 1;

/// Text in byte columns `from..to` (0-based, end excluded) of `line`, if the line reaches `to` and it is UTF-8;
/// shorter lines give what they have.
fn columns(line: &[u8], from: usize, to: usize) -> Option<&str> {
    std::str::from_utf8(line.get(from..to.min(line.len()))?).ok()
}

/// Parses a `.gro` file.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawParticles, GeometryError> {
    let mut lines = bytes.split(|&b| b == b'\n').map(|l| l.strip_suffix(b"\r").unwrap_or(l)).zip(1u64..);
    let bad = |line: u64, message: String| GeometryError::format(path, Some(line), message);
    let _title = lines.next();
    let (count_line, _) = lines.next().ok_or_else(|| bad(2, "the file ends before the atom count line".into()))?;
    let count_text = String::from_utf8_lossy(count_line);
    let count: usize =
        count_text.trim().parse().map_err(|_| bad(2, format!("'{}' is not an atom count", count_text.trim())))?;
    // The lines left after the count line (a final newline does not start one more).
    let rest = lines.clone().count();
    let rest = match bytes.last() {
        Some(b'\n') => rest.saturating_sub(1),
        _ => rest,
    };
    if rest <= count {
        return Err(bad(
            2,
            format!("atom count {count} but the file has only {rest} lines after it ({count} atom lines and a box line expected)"),
        ));
    }
    let mut raw = RawParticles {
        positions: Vec::with_capacity(count.min(bytes.len() / MIN_ATOM_LINE_BYTES)),
        smoothing: Vec::with_capacity(count.min(bytes.len() / MIN_ATOM_LINE_BYTES)),
        ..RawParticles::default()
    };
    let mut width = 0usize;
    for _ in 0..count {
        let Some((line, number)) = lines.next() else { break };
        if width == 0 {
            width = coordinate_width(line).ok_or_else(|| {
                bad(
                    number,
                    "cannot find the coordinates' precision: the first atom line needs x and y with a decimal point \
                     after column 20"
                        .into(),
                )
            })?;
        }
        let coordinate = |axis: usize| -> Result<f64, GeometryError> {
            let from = 20 + axis * width;
            let name = ["x", "y", "z"].get(axis).copied().unwrap_or("");
            let place = format!("columns {}-{}", from + 1, from + width);
            let field = line.get(from..from + width).ok_or_else(|| {
                bad(
                    number,
                    format!("the atom line ends before its {name} coordinate ({place}): {} characters", line.len()),
                )
            })?;
            let text = String::from_utf8_lossy(field);
            text.trim()
                .parse()
                .map_err(|_| bad(number, format!("{name} coordinate '{text}' ({place}) is not a number")))
        };
        let position = [coordinate(0)?, coordinate(1)?, coordinate(2)?];
        let residue = columns(line, 5, 10).unwrap_or("");
        let atom = columns(line, 10, 15).unwrap_or("");
        raw.positions.push(position);
        raw.smoothing.push(vdw_radius_angstrom(element_from_atom_name(atom, residue)) / 10.0);
    }
    if let Some((line, number)) = lines.next() {
        let text = String::from_utf8_lossy(line);
        let numbers = text.split_whitespace().map(str::parse::<f64>).collect::<Result<Vec<_>, _>>();
        if !matches!(numbers.as_deref().map(<[f64]>::len), Ok(3 | 9)) {
            return Err(bad(number, format!("the box line '{}' is not 3 or 9 numbers", text.trim())));
        }
    }
    Ok(raw)
}

/// The width of each coordinate in an atom line: the distance between the first two decimal points after the 20
/// columns of names and numbers (GROMACS's rule; `%8.3f` gives 8). At least 6 (one decimal).
fn coordinate_width(line: &[u8]) -> Option<usize> {
    let after = line.get(20..)?;
    let first = after.iter().position(|&b| b == b'.')?;
    let second = after.get(first + 1..)?.iter().position(|&b| b == b'.')? + 1;
    (6..=40).contains(&second).then_some(second)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(text: &str) -> Result<RawParticles, GeometryError> {
        parse(text.as_bytes(), Path::new("a.gro"))
    }

    const TWO: &str = "\
Two atoms, t= 0.0
    2
    1ALA     CA    1   1.000   2.000  -3.500  0.1000  0.2000  0.3000
    2CL-     CL    2  10.125   0.000   0.001
   5.00000   5.00000   5.00000
";

    #[test]
    fn two_atoms_and_a_box() {
        let p = parse_str(TWO).unwrap();
        assert_eq!(p.positions, vec![[1.0, 2.0, -3.5], [10.125, 0.0, 0.001]]);
        // CA in alanine is carbon (0.17 nm), CL in CL- chlorine (0.175 nm).
        assert_eq!(p.smoothing, vec![0.17, 0.175]);
        assert!(p.masses.is_empty() && p.values.is_empty());
        let crlf = TWO.replace('\n', "\r\n");
        assert_eq!(parse_str(&crlf).unwrap(), p);
        // Without the final newline.
        assert_eq!(parse_str(TWO.trim_end()).unwrap(), p);
    }

    #[test]
    fn precision_from_the_decimal_points() {
        // %10.5f coordinates, GROMACS's "higher precision" output.
        let text = "hi\n1\n    1SOL     OW    1   1.00001   2.00002   3.00003\n1 1 1\n";
        let p = parse_str(text).unwrap();
        assert_eq!(p.positions, vec![[1.00001, 2.00002, 3.00003]]);
        assert_eq!(p.smoothing, vec![0.152]);
        let text = "hi\n1\n    1SOL     OW    1   1   2   3\n1 1 1\n";
        assert!(parse_str(text).unwrap_err().to_string().contains("line 3: cannot find the coordinates' precision"));
    }

    #[test]
    fn errors_name_the_line_and_the_problem() {
        let e = |t: &str| parse_str(t).unwrap_err().to_string();
        assert_eq!(e(""), "a.gro line 2: the file ends before the atom count line");
        assert_eq!(e("t\nmany\n"), "a.gro line 2: 'many' is not an atom count");
        assert_eq!(
            e("t\n47681\n    1ALA     CA    1   1.000   2.000   3.000\n1 1 1\n"),
            "a.gro line 2: atom count 47681 but the file has only 2 lines after it (47681 atom lines and a box line \
             expected)"
        );
        assert_eq!(
            e("t\n1\n    1ALA     CA    1   1.000   2.000\n1 1 1\n"),
            "a.gro line 3: the atom line ends before its z coordinate (columns 37-44): 36 characters"
        );
        assert_eq!(
            e("t\n1\n    1ALA     CA    1   1.000   2.000   x.000\n1 1 1\n"),
            "a.gro line 3: z coordinate '   x.000' (columns 37-44) is not a number"
        );
        assert_eq!(
            e("t\n1\n    1ALA     CA    1   1.000   2.000   3.000\n1 1\n"),
            "a.gro line 4: the box line '1 1' is not 3 or 9 numbers"
        );
        assert!(parse(b"t\n1\n    1ALA     CA    1   1.000   2.000   3.\xff0\n1 1 1\n", Path::new("a.gro")).is_err());
        assert_eq!(parse_str("t\n0\n1 1 1\n").unwrap(), RawParticles::default());
    }
}
