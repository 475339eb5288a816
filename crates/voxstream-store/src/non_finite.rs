//! Non-finite samples (NaN, +inf, -inf) in an imported volume: refused with the position of the first one, or
//! replaced by a value the user chose (`--nan-as VALUE`). A store's value range and per-brick min/max must be finite
//! (JSON has no NaN or infinity, and one -inf would make every transfer function map the whole volume to one colour),
//! so every import passes each slice through [`check_slice`] before anything else sees it.

use crate::error::StoreError;

/// Checks one z slice (`width` samples per row, x fastest) at depth `z`: the first non-finite sample is an error
/// naming its position, unless `replacement` is given, which then takes the place of every NaN and ±inf.
pub fn check_slice(samples: &mut [f32], width: u64, z: u64, replacement: Option<f32>) -> Result<(), StoreError> {
    // The common case, all finite, costs one pass that the compiler vectorises.
    if samples.iter().all(|v| v.is_finite()) {
        return Ok(());
    }
    match replacement {
        Some(value) => {
            samples.iter_mut().filter(|v| !v.is_finite()).for_each(|v| *v = value);
            Ok(())
        }
        None => {
            let index = samples.iter().position(|v| !v.is_finite()).unwrap_or(0);
            let width = width.max(1);
            let (x, y) = (index as u64 % width, index as u64 / width);
            Err(StoreError::NonFinite { value: samples[index], position: [x, y, z] })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_non_finite_sample_is_named_by_its_position() {
        let mut slice = vec![1.0, 2.0, 3.0, f32::NEG_INFINITY, f32::NAN, 4.0];
        let error = check_slice(&mut slice, 3, 7, None).unwrap_err();
        assert!(matches!(error, StoreError::NonFinite { position: [0, 1, 7], value } if value == f32::NEG_INFINITY));
        assert!(error.to_string().contains("(0, 1, 7) is -inf"), "{error}");
    }

    #[test]
    fn a_replacement_takes_the_place_of_nan_and_both_infinities_only() {
        let mut slice = vec![f32::NAN, 2.0, f32::INFINITY, f32::NEG_INFINITY, -0.5];
        check_slice(&mut slice, 5, 0, Some(9.0)).unwrap();
        assert_eq!(slice, vec![9.0, 2.0, 9.0, 9.0, -0.5]);
    }
}
