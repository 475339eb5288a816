//! Checks of a render's inputs and output that do not stop it but would otherwise leave the user with a silently
//! useless image: a transfer function written for other units than the data's (or covering only a sliver of the
//! data's values), and an image where nothing shows.

use voxstream_render::{Image, TransferFunction};

/// Coverage below which a pixel counts as empty (less than one 8-bit step).
const EMPTY_COVERAGE: f32 = 0.5 / 255.0;

/// Fraction of the data's typical span the transfer function must overlap not to be flagged as missing the data.
const MIN_OVERLAP: f64 = 0.01;

/// Fraction of the data's typical span the transfer function must overlap not to be flagged as covering a sliver.
const MIN_COVERAGE: f64 = 0.1;

/// A warning when the transfer function changes only where the data has (almost) no values, or over less than
/// [`MIN_COVERAGE`] of the data's span (most samples then take one end's colour): `typical` is the span of the bulk
/// of the data (0.5th to 99.5th percentile where known), `full` its whole value range.
pub fn transfer_function_mismatch(tf: &TransferFunction, typical: [f64; 2], full: [f64; 2]) -> Option<String> {
    let (first, last) = (tf.points.first()?[0], tf.points.last()?[0]);
    let [low, high] = typical;
    if tf.points.len() < 2 || high <= low {
        return None;
    }
    let overlap = last.min(high) - first.max(low);
    if overlap >= MIN_COVERAGE * (high - low) {
        return None;
    }
    if overlap >= MIN_OVERLAP * (high - low) {
        let percent = (100.0 * overlap / (high - low)).round();
        return Some(format!(
            "the transfer function's values span {first} to {last}, only {percent}% of the data's typical values \
             ({low} to {high}): most samples take the colour of one of its ends; its values are in the data's units \
             (see `voxstream info`)"
        ));
    }
    Some(format!(
        "the transfer function's values span {first} to {last}, but the data's lie between {low} and {high} (all of \
         them: {} to {}): its values are in the data's units (see `voxstream info`), so the image will be one colour",
        full[0], full[1]
    ))
}

/// A warning when no pixel of `image` is covered (`surfaces`: the image draws isosurfaces; `volume`: it draws the
/// transfer function's volume, alone or around the surfaces).
pub fn empty_image(image: &Image, surfaces: bool, volume: bool) -> Option<String> {
    let covered = image.pixels.iter().any(|p| p[3] >= EMPTY_COVERAGE);
    (!covered).then(|| {
        if surfaces && volume {
            "the image is empty: neither the isosurfaces nor the volume around them shows from this camera (compare \
             --iso and --tf's values with `voxstream info`'s value range, or check --eye and --target)"
        } else if surfaces {
            "the image is empty: no ray crosses the isosurfaces from this camera (compare --iso with `voxstream \
             info`'s value range, or check --eye and --target)"
        } else {
            "the image is empty: nothing is visible under the transfer function from this camera (compare --tf's \
             values with `voxstream info`'s value range, or check --eye and --target)"
        }
        .to_string()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tf(values: &[f64]) -> TransferFunction {
        TransferFunction::new(values.iter().map(|&v| [v, 1.0, 1.0, 1.0, 0.5]).collect(), None).unwrap()
    }

    #[test]
    fn a_unit_interval_function_on_16_bit_data_is_flagged() {
        let warning = transfer_function_mismatch(&tf(&[0.0, 0.3, 1.0]), [0.0, 3400.0], [0.0, 65535.0]).unwrap();
        assert_eq!(
            warning,
            "the transfer function's values span 0 to 1, but the data's lie between 0 and 3400 (all of them: 0 to \
             65535): its values are in the data's units (see `voxstream info`), so the image will be one colour"
        );
        assert!(transfer_function_mismatch(&tf(&[5000.0, 9000.0]), [0.0, 3400.0], [0.0, 65535.0]).is_some());
    }

    #[test]
    fn a_function_over_a_sliver_of_the_data_is_flagged() {
        // An 8-bit function on 16-bit data: it overlaps 255 of 3400 (8%).
        let warning = transfer_function_mismatch(&tf(&[0.0, 128.0, 255.0]), [0.0, 3400.0], [0.0, 65535.0]).unwrap();
        assert_eq!(
            warning,
            "the transfer function's values span 0 to 255, only 8% of the data's typical values (0 to 3400): most \
             samples take the colour of one of its ends; its values are in the data's units (see `voxstream info`)"
        );
        assert!(transfer_function_mismatch(&tf(&[3300.0, 9000.0]), [0.0, 3400.0], [0.0, 65535.0]).is_some());
        assert!(transfer_function_mismatch(&tf(&[0.0, 340.0]), [0.0, 3400.0], [0.0, 65535.0]).is_none(), "10%");
    }

    #[test]
    fn functions_over_the_data_are_not_flagged() {
        assert!(transfer_function_mismatch(&tf(&[0.0, 29.0]), [0.0, 29.0], [0.0, 29.0]).is_none());
        assert!(transfer_function_mismatch(&tf(&[100.0, 5000.0]), [0.0, 3400.0], [0.0, 65535.0]).is_none());
        assert!(transfer_function_mismatch(&tf(&[0.5]), [0.0, 3400.0], [0.0, 65535.0]).is_none(), "constant");
        assert!(transfer_function_mismatch(&tf(&[0.0, 1.0]), [7.0, 7.0], [7.0, 7.0]).is_none(), "constant data");
    }

    #[test]
    fn empty_images_are_flagged() {
        let mut image = Image::new(4, 4);
        assert!(empty_image(&image, false, true).unwrap().contains("transfer function"));
        assert!(empty_image(&image, true, false).unwrap().contains("--iso with"));
        assert!(empty_image(&image, true, true).unwrap().contains("--iso and --tf"));
        image.pixels[5][3] = 0.01;
        assert!(empty_image(&image, false, true).is_none());
    }
}
