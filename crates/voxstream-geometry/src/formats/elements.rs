//! Chemical elements for the molecular readers ([`super::gro`], [`super::pdb`]): recognising an element from an atom
//! name, and its van der Waals radius.
//!
//! Radii are Bondi's (A. Bondi, "van der Waals Volumes and Radii", J. Phys. Chem. 68 (1964) 441), completed for the
//! main-group elements Bondi did not list with Mantina et al.'s consistent values (J. Phys. Chem. A 113 (2009)
//! 5806). Elements in neither (most transition metals, lanthanides, actinides but uranium) and unrecognised names
//! get [`DEFAULT_RADIUS_ANGSTROM`], carbon's radius.
//!
//! Atom names are read the way molecular-dynamics files write them: the element is the name's first letter (`CA`
//! is a protein's alpha carbon, `HG1` a hydrogen, `OW` water's oxygen), except for ions, whose residue is named
//! after the atom (`CA`/`CA` is calcium, `NA+`/`NA` sodium, CHARMM's `SOD`/`SOD` sodium too).

/// The radius of an atom whose element is not known or has no tabulated radius (carbon's), in Å.
pub const DEFAULT_RADIUS_ANGSTROM: f32 = 1.70;

/// Every element symbol, with its van der Waals radius in Å (0: none tabulated, [`DEFAULT_RADIUS_ANGSTROM`]).
const ELEMENTS: [(&str, f32); 118] = [
    ("H", 1.20),
    ("He", 1.40),
    ("Li", 1.82),
    ("Be", 1.53),
    ("B", 1.92),
    ("C", 1.70),
    ("N", 1.55),
    ("O", 1.52),
    ("F", 1.47),
    ("Ne", 1.54),
    ("Na", 2.27),
    ("Mg", 1.73),
    ("Al", 1.84),
    ("Si", 2.10),
    ("P", 1.80),
    ("S", 1.80),
    ("Cl", 1.75),
    ("Ar", 1.88),
    ("K", 2.75),
    ("Ca", 2.31),
    ("Sc", 0.0),
    ("Ti", 0.0),
    ("V", 0.0),
    ("Cr", 0.0),
    ("Mn", 0.0),
    ("Fe", 0.0),
    ("Co", 0.0),
    ("Ni", 1.63),
    ("Cu", 1.40),
    ("Zn", 1.39),
    ("Ga", 1.87),
    ("Ge", 2.11),
    ("As", 1.85),
    ("Se", 1.90),
    ("Br", 1.85),
    ("Kr", 2.02),
    ("Rb", 3.03),
    ("Sr", 2.49),
    ("Y", 0.0),
    ("Zr", 0.0),
    ("Nb", 0.0),
    ("Mo", 0.0),
    ("Tc", 0.0),
    ("Ru", 0.0),
    ("Rh", 0.0),
    ("Pd", 1.63),
    ("Ag", 1.72),
    ("Cd", 1.58),
    ("In", 1.93),
    ("Sn", 2.17),
    ("Sb", 2.06),
    ("Te", 2.06),
    ("I", 1.98),
    ("Xe", 2.16),
    ("Cs", 3.43),
    ("Ba", 2.68),
    ("La", 0.0),
    ("Ce", 0.0),
    ("Pr", 0.0),
    ("Nd", 0.0),
    ("Pm", 0.0),
    ("Sm", 0.0),
    ("Eu", 0.0),
    ("Gd", 0.0),
    ("Tb", 0.0),
    ("Dy", 0.0),
    ("Ho", 0.0),
    ("Er", 0.0),
    ("Tm", 0.0),
    ("Yb", 0.0),
    ("Lu", 0.0),
    ("Hf", 0.0),
    ("Ta", 0.0),
    ("W", 0.0),
    ("Re", 0.0),
    ("Os", 0.0),
    ("Ir", 0.0),
    ("Pt", 1.72),
    ("Au", 1.66),
    ("Hg", 1.55),
    ("Tl", 1.96),
    ("Pb", 2.02),
    ("Bi", 2.07),
    ("Po", 1.97),
    ("At", 2.02),
    ("Rn", 2.20),
    ("Fr", 3.48),
    ("Ra", 2.83),
    ("Ac", 0.0),
    ("Th", 0.0),
    ("Pa", 0.0),
    ("U", 1.86),
    ("Np", 0.0),
    ("Pu", 0.0),
    ("Am", 0.0),
    ("Cm", 0.0),
    ("Bk", 0.0),
    ("Cf", 0.0),
    ("Es", 0.0),
    ("Fm", 0.0),
    ("Md", 0.0),
    ("No", 0.0),
    ("Lr", 0.0),
    ("Rf", 0.0),
    ("Db", 0.0),
    ("Sg", 0.0),
    ("Bh", 0.0),
    ("Hs", 0.0),
    ("Mt", 0.0),
    ("Ds", 0.0),
    ("Rg", 0.0),
    ("Cn", 0.0),
    ("Nh", 0.0),
    ("Fl", 0.0),
    ("Mc", 0.0),
    ("Lv", 0.0),
    ("Ts", 0.0),
    ("Og", 0.0),
];

/// CHARMM's ion residue and atom names, which are not element symbols.
const ION_ALIASES: [(&str, &str); 8] = [
    ("SOD", "Na"),
    ("POT", "K"),
    ("CLA", "Cl"),
    ("CAL", "Ca"),
    ("CES", "Cs"),
    ("LIT", "Li"),
    ("RUB", "Rb"),
    ("BAR", "Ba"),
];

/// The element whose symbol is `text` (any letter case, surrounding blanks ignored), in its usual spelling.
pub fn element_symbol(text: &str) -> Option<&'static str> {
    let text = text.trim();
    ELEMENTS.iter().map(|(symbol, _)| *symbol).find(|symbol| symbol.eq_ignore_ascii_case(text))
}

/// The van der Waals radius of `element` (a symbol from [`element_symbol`]) in Å; [`DEFAULT_RADIUS_ANGSTROM`] when
/// it is `None` or has none tabulated.
pub fn vdw_radius_angstrom(element: Option<&str>) -> f32 {
    element
        .and_then(|e| ELEMENTS.iter().find(|(symbol, _)| *symbol == e))
        .map(|&(_, radius)| radius)
        .filter(|&radius| radius > 0.0)
        .unwrap_or(DEFAULT_RADIUS_ANGSTROM)
}

/// A name without surrounding blanks, charge signs and digits (`NA+` → `NA`, `ZN2` → `ZN`, `1HD2` → `HD`).
fn bare(name: &str) -> &str {
    name.trim().trim_matches(|c: char| c == '+' || c == '-' || c.is_ascii_digit())
}

/// The element of an ion: an atom named like its residue (`CA` in `CA`, `NA` in `NA+`, `SOD` in `SOD`).
pub fn ion_element(atom_name: &str, residue_name: &str) -> Option<&'static str> {
    let (atom, residue) = (bare(atom_name), bare(residue_name));
    if atom.is_empty() || !atom.eq_ignore_ascii_case(residue) {
        return None;
    }
    element_symbol(atom)
        .or_else(|| ION_ALIASES.iter().find(|(alias, _)| alias.eq_ignore_ascii_case(atom)).map(|&(_, element)| element))
}

/// The element named by the first letter of `atom_name` (leading digits skipped, `1HD2` → H), if it is an element.
pub fn first_letter_element(atom_name: &str) -> Option<&'static str> {
    let letter = atom_name.trim().chars().find(|c| !c.is_ascii_digit())?;
    if !letter.is_ascii_alphabetic() {
        return None;
    }
    element_symbol(letter.encode_utf8(&mut [0; 4]))
}

/// The element of an atom from its name and its residue's name, as molecular-dynamics files write them: an ion's
/// (see [`ion_element`]), otherwise the name's first letter.
pub fn element_from_atom_name(atom_name: &str, residue_name: &str) -> Option<&'static str> {
    ion_element(atom_name, residue_name).or_else(|| first_letter_element(atom_name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_give_elements() {
        assert_eq!(element_from_atom_name("CA", "ALA"), Some("C"));
        assert_eq!(element_from_atom_name("CA", "CA"), Some("Ca"));
        assert_eq!(element_from_atom_name("NA", "NA+"), Some("Na"));
        assert_eq!(element_from_atom_name("CL", "CL-"), Some("Cl"));
        assert_eq!(element_from_atom_name("ZN", "ZN2"), Some("Zn"));
        assert_eq!(element_from_atom_name("SOD", "SOD"), Some("Na"));
        assert_eq!(element_from_atom_name("HG1", "MET"), Some("H"));
        assert_eq!(element_from_atom_name("1HD2", "LEU"), Some("H"));
        assert_eq!(element_from_atom_name("OW", "SOL"), Some("O"));
        assert_eq!(element_from_atom_name("MW", "SOL"), None);
        assert_eq!(element_from_atom_name("", ""), None);
        assert_eq!(element_from_atom_name("é", "é"), None);
        assert_eq!(element_symbol(" fe "), Some("Fe"));
    }

    #[test]
    fn radii_are_bondi_or_default() {
        assert_eq!(vdw_radius_angstrom(Some("H")), 1.20);
        assert_eq!(vdw_radius_angstrom(Some("N")), 1.55);
        assert_eq!(vdw_radius_angstrom(Some("O")), 1.52);
        assert_eq!(vdw_radius_angstrom(Some("S")), 1.80);
        assert_eq!(vdw_radius_angstrom(Some("Fe")), DEFAULT_RADIUS_ANGSTROM);
        assert_eq!(vdw_radius_angstrom(None), DEFAULT_RADIUS_ANGSTROM);
        assert_eq!(ELEMENTS.iter().filter(|(s, _)| element_symbol(s) != Some(*s)).count(), 0);
    }
}
