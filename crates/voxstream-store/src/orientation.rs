//! Which anatomical direction each sample axis points to: read from the files that say it (NIfTI's qform or sform,
//! DICOM's Image Orientation (Patient), NRRD's `space`, MetaImage's direction, other tools' OME-Zarr axes), given
//! with `import --orientation`, kept in the store and written to its OME axes as OME-NGFF's anatomical orientation
//! (RFC-4: `"orientation": {"type": "anatomical", "value": "left-to-right"}`), shown by `info`, and used by the
//! default camera, so that a head is seen from its face whichever way its file stores it.
//!
//! It is named by three letters in the RAS tradition of nibabel's `aff2axcodes` and 3D Slicer: the letter of the
//! direction each axis (x, y, z) *points to*: `RAS` is NIfTI's MNI space (x towards the patient's right, y towards
//! the front, z up), `LPS` DICOM's patient axes. A volume whose axes are rotated obliquely is given the nearest
//! letters; the rotation itself is not applied (the volume stays axis-aligned in voxstream's world, as in VTK's
//! image data). A volume without one (raw samples, TIFF stacks, NumPy arrays, meshes) keeps the index-axes
//! convention: `+z` up, seen from the `−y` side.

use std::fmt;

/// One of the six directions of the patient's axes (left/right, posterior/anterior, inferior/superior).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Towards {
    /// The RAS axis: 0 left–right, 1 posterior–anterior, 2 inferior–superior.
    axis: u8,
    /// Pointing to the right, the front or up (the RAS letters) rather than the opposite.
    positive: bool,
}

/// The letters of each RAS axis: (negative, positive).
const LETTERS: [(char, char); 3] = [('L', 'R'), ('P', 'A'), ('I', 'S')];

/// OME-NGFF RFC-4's values for each RAS axis: (pointing to the negative letter, pointing to the positive one).
const RFC4_VALUES: [(&str, &str); 3] = [
    ("right-to-left", "left-to-right"),
    ("anterior-to-posterior", "posterior-to-anterior"),
    ("superior-to-inferior", "inferior-to-superior"),
];

impl Towards {
    /// The direction a letter names (`R`, `L`, `A`, `P`, `S`, `I`, either case).
    pub fn from_letter(letter: char) -> Option<Towards> {
        let upper = letter.to_ascii_uppercase();
        LETTERS.iter().enumerate().find_map(|(axis, &(negative, positive))| {
            (upper == negative || upper == positive)
                .then_some(Towards { axis: axis as u8, positive: upper == positive })
        })
    }

    /// Its letter.
    pub fn letter(self) -> char {
        let (negative, positive) = LETTERS[self.axis as usize];
        if self.positive {
            positive
        } else {
            negative
        }
    }

    /// OME-NGFF's name of an axis pointing this way (`left-to-right` for `R`).
    pub fn rfc4_value(self) -> &'static str {
        let (negative, positive) = RFC4_VALUES[self.axis as usize];
        if self.positive {
            positive
        } else {
            negative
        }
    }

    /// The direction an OME-NGFF anatomical orientation value names, for the six of the human body's axes.
    pub fn from_rfc4_value(value: &str) -> Option<Towards> {
        RFC4_VALUES.iter().enumerate().find_map(|(axis, &(negative, positive))| {
            (value == negative || value == positive)
                .then_some(Towards { axis: axis as u8, positive: value == positive })
        })
    }

    /// The body axis it lies along: 0 left–right, 1 posterior–anterior, 2 inferior–superior.
    pub fn body_axis(self) -> usize {
        self.axis as usize
    }

    /// The unit vector of this direction in RAS coordinates.
    pub fn ras(self) -> [f64; 3] {
        let mut v = [0.0; 3];
        v[self.axis as usize] = if self.positive { 1.0 } else { -1.0 };
        v
    }
}

/// The direction each sample axis (x, y, z) points to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Orientation([Towards; 3]);

impl Orientation {
    /// RAS: NIfTI's world axes (x to the right, y to the front, z up).
    pub const RAS: Orientation = Orientation([
        Towards { axis: 0, positive: true },
        Towards { axis: 1, positive: true },
        Towards { axis: 2, positive: true },
    ]);

    /// LSA: mesh and particle files' convention (`+y` up, `+z` towards the viewer of an OpenGL camera, the front of
    /// a model facing it; `+x` its left).
    pub const LSA: Orientation = Orientation([
        Towards { axis: 0, positive: false },
        Towards { axis: 2, positive: true },
        Towards { axis: 1, positive: true },
    ]);

    /// An orientation from one direction per axis, refused unless they name three different body axes.
    pub fn new(axes: [Towards; 3]) -> Result<Orientation, String> {
        let [a, b, c] = axes.map(|t| t.axis);
        if a == b || a == c || b == c {
            let letters: String = axes.iter().map(|t| t.letter()).collect();
            return Err(format!(
                "'{letters}' names one body axis twice: give one of R/L, one of A/P and one of S/I, e.g. RAS or LPS"
            ));
        }
        Ok(Orientation(axes))
    }

    /// The orientation three letters name (`RAS`, `lps`, `PIR`), with a message naming the problem otherwise.
    pub fn parse(code: &str) -> Result<Orientation, String> {
        let letters: Vec<char> = code.trim().chars().collect();
        let towards: Option<Vec<Towards>> = letters.iter().map(|&c| Towards::from_letter(c)).collect();
        match towards {
            Some(t) if t.len() == 3 => Orientation::new([t[0], t[1], t[2]]),
            _ => Err(format!(
                "'{code}' is not an orientation: give three letters, the direction each axis (x, y, z) points to, \
                 one of R/L, one of A/P and one of S/I (RAS for NIfTI's MNI space, LPS for DICOM's patient axes)"
            )),
        }
    }

    /// The nearest orientation to sample axes whose directions are the columns of `columns` (column `a` is axis
    /// `a`'s direction) in RAS coordinates: each axis gets the body axis its direction is closest to. `None` when
    /// the directions are not finite, or two of them lie nearest the same body axis (a degenerate matrix).
    pub fn nearest_ras(columns: [[f64; 3]; 3]) -> Option<Orientation> {
        let mut axes = [Towards { axis: 0, positive: true }; 3];
        for (a, column) in columns.iter().enumerate() {
            if !column.iter().all(|v| v.is_finite()) {
                return None;
            }
            let (axis, value) =
                column.iter().enumerate().max_by(|x, y| x.1.abs().total_cmp(&y.1.abs())).expect("three components");
            if *value == 0.0 {
                return None;
            }
            axes[a] = Towards { axis: axis as u8, positive: *value > 0.0 };
        }
        Orientation::new(axes).ok()
    }

    /// [`Orientation::nearest_ras`] for directions in LPS coordinates (DICOM's and ITK's patient axes).
    pub fn nearest_lps(columns: [[f64; 3]; 3]) -> Option<Orientation> {
        Orientation::nearest_ras(columns.map(|[x, y, z]| [-x, -y, z]))
    }

    /// The direction axis `axis` (0 x, 1 y, 2 z) points to.
    pub fn axis(&self, axis: usize) -> Towards {
        self.0[axis]
    }

    /// Its three letters (`RAS`).
    pub fn code(&self) -> String {
        self.0.iter().map(|t| t.letter()).collect()
    }

    /// A direction given in RAS coordinates, in the volume's axes (x, y, z): where the world points that way.
    pub fn volume_direction(&self, ras: [f64; 3]) -> [f64; 3] {
        self.0.map(|t| if t.positive { ras[t.axis as usize] } else { -ras[t.axis as usize] })
    }
}

impl fmt::Display for Orientation {
    /// `RAS (x left-to-right, y posterior-to-anterior, z inferior-to-superior)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.0.map(Towards::rfc4_value);
        write!(f, "{} (x {x}, y {y}, z {z})", self.code())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_bad_ones_are_named() {
        for code in ["RAS", "LPS", "PIR", "ASL", "ILA"] {
            assert_eq!(Orientation::parse(code).unwrap().code(), code);
        }
        assert_eq!(Orientation::parse(" ras ").unwrap(), Orientation::RAS);
        assert_eq!(Orientation::LSA.code(), "LSA");
        let twice = Orientation::parse("RLS").unwrap_err();
        assert!(twice.contains("names one body axis twice"), "{twice}");
        for bad in ["RA", "RASX", "XYZ", ""] {
            let error = Orientation::parse(bad).unwrap_err();
            assert!(error.contains("three letters"), "{bad}: {error}");
        }
        assert_eq!(
            Orientation::RAS.to_string(),
            "RAS (x left-to-right, y posterior-to-anterior, z inferior-to-superior)"
        );
    }

    #[test]
    fn rfc4_values_name_the_direction_an_axis_points_to() {
        let lps = Orientation::parse("LPS").unwrap();
        assert_eq!(lps.axis(0).rfc4_value(), "right-to-left");
        assert_eq!(lps.axis(1).rfc4_value(), "anterior-to-posterior");
        assert_eq!(lps.axis(2).rfc4_value(), "inferior-to-superior");
        for letter in "RLAPSI".chars() {
            let towards = Towards::from_letter(letter).unwrap();
            assert_eq!(Towards::from_rfc4_value(towards.rfc4_value()), Some(towards));
        }
        assert_eq!(Towards::from_rfc4_value("dorsal-to-ventral"), None);
    }

    #[test]
    fn the_nearest_orientation_of_rotated_axes() {
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert_eq!(Orientation::nearest_ras(identity), Some(Orientation::RAS));
        assert_eq!(Orientation::nearest_lps(identity).unwrap().code(), "LPS");
        // An axial series tilted by 20° about x, with x flipped: columns are the axes' directions.
        let (s, c) = 20f64.to_radians().sin_cos();
        let tilted = [[-1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]];
        assert_eq!(Orientation::nearest_ras(tilted).unwrap().code(), "LAS");
        // A sagittal stack: x along A, y along −S (rows top to bottom), z along R.
        let sagittal = [[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]];
        assert_eq!(Orientation::nearest_ras(sagittal).unwrap().code(), "AIR");
        // Degenerate: two axes along one body axis, a zero or non-finite column.
        assert_eq!(Orientation::nearest_ras([[1.0, 0.1, 0.0], [0.9, 0.2, 0.0], [0.0, 0.0, 1.0]]), None);
        assert_eq!(Orientation::nearest_ras([[0.0; 3], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), None);
        assert_eq!(Orientation::nearest_ras([[f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), None);
    }

    #[test]
    fn ras_directions_land_on_the_axes_that_point_there() {
        let pir = Orientation::parse("PIR").unwrap();
        // Anterior is −x, superior −y, right +z.
        assert_eq!(pir.volume_direction([0.0, 1.0, 0.0]), [-1.0, 0.0, 0.0]);
        assert_eq!(pir.volume_direction([0.0, 0.0, 1.0]), [0.0, -1.0, 0.0]);
        assert_eq!(pir.volume_direction([1.0, 0.0, 0.0]), [0.0, 0.0, 1.0]);
        assert_eq!(Orientation::RAS.volume_direction([0.3, -0.2, 0.1]), [0.3, -0.2, 0.1]);
    }
}
