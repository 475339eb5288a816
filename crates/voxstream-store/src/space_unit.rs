//! The unit of a volume's spacing and origin, as OME-Zarr names it (the `unit` of a space axis, which OME-NGFF 0.5
//! limits to a list of UDUNITS-2 names): read from NIfTI's `xyzt_units` and NRRD's `space units`, given with
//! `import --unit`, written to the store's axes and shown by `info`. A volume without one has spacing in whatever
//! unit its file used; stores written before units were kept have none and read as before.

use std::fmt;

/// The space units OME-NGFF 0.5 allows (its `axes` section), in its order.
pub const OME_SPACE_UNITS: [&str; 26] = [
    "angstrom",
    "attometer",
    "centimeter",
    "decimeter",
    "exameter",
    "femtometer",
    "foot",
    "gigameter",
    "hectometer",
    "inch",
    "kilometer",
    "megameter",
    "meter",
    "micrometer",
    "mile",
    "millimeter",
    "nanometer",
    "parsec",
    "petameter",
    "picometer",
    "terameter",
    "yard",
    "yoctometer",
    "yottameter",
    "zeptometer",
    "zettameter",
];

/// Common spellings of the units scans use, and the OME name each stands for.
const ALIASES: [(&str, &str); 16] = [
    ("mm", "millimeter"),
    ("millimetre", "millimeter"),
    ("um", "micrometer"),
    ("µm", "micrometer"),
    ("μm", "micrometer"),
    ("micron", "micrometer"),
    ("micrometre", "micrometer"),
    ("nm", "nanometer"),
    ("nanometre", "nanometer"),
    ("cm", "centimeter"),
    ("centimetre", "centimeter"),
    ("m", "meter"),
    ("metre", "meter"),
    ("km", "kilometer"),
    ("pm", "picometer"),
    ("Å", "angstrom"),
];

/// One of [`OME_SPACE_UNITS`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SpaceUnit(&'static str);

impl SpaceUnit {
    /// The OME-Zarr unit named `name`, or a common abbreviation or spelling of one (`mm`, `µm`, `micron`,
    /// `millimetre`, a plural); `None` for anything else.
    pub fn from_name(name: &str) -> Option<SpaceUnit> {
        let name = name.trim();
        let lookup = |n: &str| {
            OME_SPACE_UNITS
                .iter()
                .find(|u| **u == n)
                .copied()
                .or_else(|| ALIASES.iter().find(|(alias, _)| *alias == n).map(|(_, u)| *u))
        };
        let lower = name.to_lowercase();
        lookup(name)
            .or_else(|| lookup(&lower))
            .or_else(|| lower.strip_suffix('s').filter(|s| s.len() > 2).and_then(lookup))
            .map(SpaceUnit)
    }

    /// Parses a user's unit (`--unit`): the error is one line naming the OME-Zarr units.
    pub fn parse(name: &str) -> Result<SpaceUnit, String> {
        SpaceUnit::from_name(name).ok_or_else(|| {
            format!(
                "'{name}' is not an OME-Zarr space unit: use one of {} (or mm, µm, nm, cm, m)",
                OME_SPACE_UNITS.join(", ")
            )
        })
    }

    /// The unit of NIfTI-1's `xyzt_units` (its low 3 bits: 1 meter, 2 millimeter, 3 micron; 0 unknown).
    pub fn from_nifti(xyzt_units: u8) -> Option<SpaceUnit> {
        match xyzt_units & 0x07 {
            1 => Some(SpaceUnit("meter")),
            2 => Some(SpaceUnit("millimeter")),
            3 => Some(SpaceUnit("micrometer")),
            _ => None,
        }
    }

    /// The OME-Zarr name (`millimeter`).
    pub fn name(self) -> &'static str {
        self.0
    }
}

impl fmt::Display for SpaceUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_abbreviations_and_plurals_map_to_ome_names() {
        for (given, ome) in [
            ("millimeter", "millimeter"),
            ("mm", "millimeter"),
            ("Millimetres", "millimeter"),
            ("µm", "micrometer"),
            ("microns", "micrometer"),
            ("m", "meter"),
            ("angstrom", "angstrom"),
            ("Å", "angstrom"),
        ] {
            assert_eq!(SpaceUnit::from_name(given).map(SpaceUnit::name), Some(ome), "{given}");
        }
        for bad in ["", "furlong", "ms", "pixel", "s"] {
            assert_eq!(SpaceUnit::from_name(bad), None, "{bad}");
        }
        let error = SpaceUnit::parse("furlong").unwrap_err();
        assert!(error.contains("'furlong' is not an OME-Zarr space unit") && error.contains("millimeter"));
        assert!(!error.contains('\n'));
    }

    #[test]
    fn nifti_spatial_unit_codes() {
        assert_eq!(SpaceUnit::from_nifti(2 | 8).map(SpaceUnit::name), Some("millimeter"));
        assert_eq!(SpaceUnit::from_nifti(3).map(SpaceUnit::name), Some("micrometer"));
        assert_eq!(SpaceUnit::from_nifti(1).map(SpaceUnit::name), Some("meter"));
        assert_eq!(SpaceUnit::from_nifti(0), None);
        assert_eq!(SpaceUnit::from_nifti(8), None);
    }
}
