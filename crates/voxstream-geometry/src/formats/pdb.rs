//! Protein Data Bank files (`.pdb`, <https://www.wwpdb.org/documentation/file-format-content/format33/sect9.html>):
//! the `ATOM` and `HETATM` records of the first model as particles, positions in the file's Å, each atom's van der
//! Waals radius (Å) as its smoothing length.
//!
//! Coordinates are columns 31-38, 39-46 and 47-54. The element is columns 77-78 when they hold one; otherwise it
//! comes from the atom name (columns 13-16) by the PDB's rule, that an element's symbol is right-justified in
//! columns 13-14 (so ` CA ` is an alpha carbon and `CA  ` calcium; a four-character name starting with `H` in
//! column 13, like `HG11`, is a hydrogen), and an ion named like its residue is that ion. Files that start every
//! name in column 13 (CHARMM's and NAMD's, whose `CA` is an alpha carbon) follow no such rule: there the element
//! is the name's first letter, or the ion's ([`super::elements`]). The element's Bondi radius goes into `smoothing`.
//! Of the atoms with alternate locations, those of the first location named in the file are kept. Reading stops at
//! the first `ENDMDL` (or `END`). Masses and values are left empty.
//!
//! Not read: models after the first; `ANISOU`, `CONECT` and the other records; hybrid-36 serials are not needed.

use std::path::Path;

use super::elements::{element_from_atom_name, element_symbol, first_letter_element, ion_element, vdw_radius_angstrom};
use crate::error::GeometryError;
use crate::particles::RawParticles;

fn is_atom(line: &[u8]) -> bool {
    line.starts_with(b"ATOM") || line.starts_with(b"HETATM")
}

/// The lines up to the first `ENDMDL` or `END` record, `\r` removed, with their numbers.
fn first_model(bytes: &[u8]) -> impl Iterator<Item = (&[u8], u64)> {
    bytes
        .split(|&b| b == b'\n')
        .map(|l| l.strip_suffix(b"\r").unwrap_or(l))
        .zip(1u64..)
        .take_while(|(l, _)| !(l.starts_with(b"ENDMDL") || l.trim_ascii_end() == b"END"))
}

/// Text of the 1-based, inclusive columns `from`-`to` of `line` (what the line has of them), blanks trimmed.
fn columns(line: &[u8], from: usize, to: usize) -> &str {
    let field = line.get(from - 1..to.min(line.len())).unwrap_or(&[]);
    std::str::from_utf8(field).unwrap_or("").trim()
}

/// Parses a `.pdb` file.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawParticles, GeometryError> {
    // Whether some name starts in column 14: then the file follows the PDB's justification of names.
    let justified = first_model(bytes)
        .any(|(l, _)| is_atom(l) && l.get(12) == Some(&b' ') && l.get(13).is_some_and(u8::is_ascii_alphabetic));
    let mut raw = RawParticles::default();
    let mut first_alternate: Option<u8> = None;
    for (line, number) in first_model(bytes) {
        if !is_atom(line) {
            continue;
        }
        let bad = |message: String| GeometryError::format(path, Some(number), message);
        let alternate = line.get(16).copied().unwrap_or(b' ');
        if alternate != b' ' && *first_alternate.get_or_insert(alternate) != alternate {
            continue;
        }
        let record = columns(line, 1, 6);
        let coordinate = |axis: usize, from: usize| -> Result<f64, GeometryError> {
            let name = ["x", "y", "z"].get(axis).copied().unwrap_or("");
            let to = from + 7;
            let field = line.get(from - 1..to).ok_or_else(|| {
                bad(format!("the {record} record ends before its {name} coordinate (columns {from}-{to})"))
            })?;
            let text = String::from_utf8_lossy(field);
            text.trim()
                .parse()
                .map_err(|_| bad(format!("{name} coordinate '{text}' (columns {from}-{to}) is not a number")))
        };
        raw.positions.push([coordinate(0, 31)?, coordinate(1, 39)?, coordinate(2, 47)?]);
        let element = element_symbol(columns(line, 77, 78)).or_else(|| element_from_name(line, justified));
        raw.smoothing.push(vdw_radius_angstrom(element));
    }
    if raw.positions.is_empty() {
        return Err(GeometryError::format(path, None, "no ATOM or HETATM records (before the first ENDMDL)"));
    }
    Ok(raw)
}

/// The element named by the atom name (columns 13-16) and the residue name (columns 18-20).
fn element_from_name(line: &[u8], justified: bool) -> Option<&'static str> {
    let name = columns(line, 13, 16);
    let residue = columns(line, 18, 20);
    if !justified {
        return element_from_atom_name(name, residue);
    }
    if let Some(ion) = ion_element(name, residue) {
        return Some(ion);
    }
    let two_letters = line.get(12..14).filter(|l| l.iter().all(u8::is_ascii_alphabetic));
    match two_letters {
        Some(_) if name.len() == 4 && name.starts_with(['H', 'h']) => Some("H"),
        Some(letters) => {
            std::str::from_utf8(letters).ok().and_then(element_symbol).or_else(|| first_letter_element(name))
        }
        None => first_letter_element(name),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(text: &str) -> Result<RawParticles, GeometryError> {
        parse(text.as_bytes(), Path::new("m.pdb"))
    }

    const MODELS: &str = "\
HEADER    TEST
CRYST1   80.017   80.017   80.017  90.00  90.00  90.00 P 1           1
MODEL        1
ATOM      1  N   ALA A   1      -8.901   4.127  -0.555  1.00  0.00           N
ATOM      2  CA  ALA A   1      -8.608   3.135  -1.618  1.00  0.00           C
ATOM      3  HB1AALA A   1       1.000   1.000   1.000  0.50  0.00           H
ATOM      4  HB1BALA A   1       1.100   1.000   1.000  0.50  0.00           H
HETATM    5 FE   HEM A   2      03.000  00.000  00.000  1.00 00.00          FE
HETATM    6  O   HOH A   3       0.000   0.000   3.000  1.00 00.00
HETATM    7 CA    CA A   4       0.000   3.000   0.000  1.00 00.00
HETATM    8 CL   LIG A   5       0.000   3.000   0.000  1.00 00.00
ATOM      9 HG11 VAL A   6       0.000   3.000   0.000  1.00 00.00
ATOM     10  S   MET A   7       1.000   2.000   3.000  1.00 00.00           s
ENDMDL
MODEL        2
ATOM      1  N   ALA A   1      -9.901   4.127  -0.555  1.00  0.00           N
ENDMDL
END
";

    #[test]
    fn first_model_with_elements_from_columns_and_names() {
        let p = parse_str(MODELS).unwrap();
        assert_eq!(p.positions.len(), 9, "{:?}", p.positions);
        assert_eq!(p.positions[0], [-8.901, 4.127, -0.555]);
        // The alternate location B of atom 4 is skipped.
        assert_eq!(p.positions[2], [1.0, 1.0, 1.0]);
        assert_eq!(p.positions[3], [3.0, 0.0, 0.0]);
        // N, C, H, Fe (element column), O (name), Ca (ion), Cl (name in column 13), H (HG11), S.
        assert_eq!(p.smoothing, vec![1.55, 1.70, 1.20, 1.70, 1.52, 2.31, 1.75, 1.20, 1.80]);
        assert!(p.masses.is_empty() && p.values.is_empty());
        assert_eq!(parse_str(&MODELS.replace('\n', "\r\n")).unwrap(), p);
    }

    #[test]
    fn names_starting_in_column_13_everywhere_are_first_letters() {
        // CHARMM style: CA is an alpha carbon, HG1 and CE are hydrogen and carbon, ions named like their residue.
        let text = "\
ATOM      1 N    MET     1     -11.921  26.307  10.410  1.00 38.38      4AKE
ATOM      2 CA   MET     1     -10.929  25.652  11.311  1.00 26.14      4AKE
ATOM      3 HG1  MET     1     -10.136  23.879  13.356  1.00  0.00      4AKE
ATOM      4 CE   MET     1     -10.466  27.039  15.229  1.00 39.02      4AKE
ATOM      5 SOD  SOD     2       0.000   0.000   0.000  1.00  0.00      ION
ATOM      6 ZN   ZN2     3       0.000   0.000   0.000  1.00  0.00      ION
";
        let p = parse_str(text).unwrap();
        assert_eq!(p.smoothing, vec![1.55, 1.70, 1.20, 1.70, 2.27, 1.39]);
        assert_eq!(p.positions[3], [-10.466, 27.039, 15.229]);
    }

    #[test]
    fn errors_name_the_line_and_the_problem() {
        let e = |t: &str| parse_str(t).unwrap_err().to_string();
        assert_eq!(
            e("REMARK\nATOM      1  N   ALA A   1      -8.901   4.127\n"),
            "m.pdb line 2: the ATOM record ends before its z coordinate (columns 47-54)"
        );
        assert_eq!(
            e("HETATM    1  N   ALA A   1      -8.901   4.1x7  -0.555\n"),
            "m.pdb line 1: y coordinate '   4.1x7' (columns 39-46) is not a number"
        );
        assert_eq!(e("HEADER\nENDMDL\nATOM\n"), "m.pdb: no ATOM or HETATM records (before the first ENDMDL)");
        assert!(parse(b"ATOM  \xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff", Path::new("m.pdb")).is_err());
        let p = parse(
            b"ATOM      1 \xffA   ALA A   1      -8.901   4.127  -0.555   \xff\xff \xff\xff\n",
            Path::new("m.pdb"),
        );
        assert_eq!(p.unwrap().smoothing, vec![1.70]);
    }
}
