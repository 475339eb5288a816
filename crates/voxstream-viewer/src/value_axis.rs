//! The value axis under the transfer-function editor's histogram: tick labels in data units.
//!
//! The axis names its two ends (the plot's lowest and highest value) and, between them, round values: multiples of
//! 1, 2 or 5 times a power of ten, as many as fit without labels running into each other (Heckbert's "nice numbers",
//! Graphics Gems I, 1990). Pure arithmetic, so it is tested without a window.

/// Points a label is given (its text is centred on its tick; the two ends are aligned inwards).
pub const LABEL_WIDTH: f32 = 48.0;

/// One tick of the axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Tick {
    /// The data value.
    pub value: f64,
    /// Where it is along the axis: 0 at the low end, 1 at the high end.
    pub position: f32,
    /// Its label.
    pub label: String,
    /// Whether it is one of the axis's two ends (drawn aligned inwards) rather than a round value between them.
    pub is_end: bool,
}

/// The ticks of an axis from `lo` to `hi` drawn `width` points wide: both ends, then round values between them whose
/// labels keep [`LABEL_WIDTH`] apart from each other and from the ends. Empty when the range is not finite; one tick
/// when it is a single value.
pub fn value_ticks(lo: f64, hi: f64, width: f32) -> Vec<Tick> {
    if !lo.is_finite() || !hi.is_finite() || hi < lo || !width.is_finite() || width <= 0.0 {
        return Vec::new();
    }
    let span = hi - lo;
    if span == 0.0 || !span.is_finite() {
        return vec![Tick { value: lo, position: 0.0, label: format_value(lo, 0.0), is_end: true }];
    }
    // At most one round label per two label widths: the spacing the step must reach.
    let fit = ((width / (2.0 * LABEL_WIDTH)).floor() as usize).clamp(1, 10);
    let step = nice_step(span / fit as f64);
    let position = |value: f64| ((value - lo) / span) as f32;
    // The ends are not round: written finer than the step, without trailing zeros.
    let end = |value: f64| trim_zeros(format_value(value, step / 100.0));
    let mut ticks = vec![
        Tick { value: lo, position: 0.0, label: end(lo), is_end: true },
        Tick { value: hi, position: 1.0, label: end(hi), is_end: true },
    ];
    // Round labels are centred on their tick; the ends' labels lie inside the axis, one label width long.
    let clear = |at: f32| at * width >= 1.5 * LABEL_WIDTH && (1.0 - at) * width >= 1.5 * LABEL_WIDTH;
    let first = (lo / step).ceil();
    let last = (hi / step).floor();
    if first.is_finite() && last.is_finite() && (0.0..100.0).contains(&(last - first)) {
        for i in 0..=(last - first) as u32 {
            // Multiples of the step, each from its integer (no drift), and -0 written as 0.
            let value = multiple(first + f64::from(i), step) + 0.0;
            if clear(position(value)) {
                ticks.push(Tick { value, position: position(value), label: format_value(value, step), is_end: false });
            }
        }
    }
    ticks
}

/// The round step nearest above `raw`: 1, 2 or 5 times a power of ten.
pub fn nice_step(raw: f64) -> f64 {
    if !raw.is_finite() || raw <= 0.0 {
        return 1.0;
    }
    let magnitude = 10f64.powf(raw.log10().floor());
    let fraction = raw / magnitude;
    let nice = if fraction <= 1.0 {
        1.0
    } else if fraction <= 2.0 {
        2.0
    } else if fraction <= 5.0 {
        5.0
    } else {
        10.0
    };
    nice * magnitude
}

/// `k` times the round `step`, as the decimal it stands for: 3 × 0.2 is 0.6, not 0.6000000000000001 (a division by
/// an exact power of ten rounds once).
fn multiple(k: f64, step: f64) -> f64 {
    let exponent = step.log10().floor() as i32;
    let nice = (step / 10f64.powi(exponent)).round();
    if exponent >= 0 {
        k * nice * 10f64.powi(exponent)
    } else {
        k * nice / 10f64.powi(-exponent)
    }
}

/// `value` written with the decimals `resolution` needs (none for a resolution of 1 or more, 0: as short as Rust
/// writes it), in scientific notation when very large or very small.
pub fn format_value(value: f64, resolution: f64) -> String {
    let resolved = resolution.is_finite() && resolution > 0.0;
    let magnitude = value.abs();
    if magnitude == 0.0 || (resolved && magnitude < resolution / 2.0) {
        return "0".into();
    }
    if !(1e-3..1e6).contains(&magnitude) {
        return format!("{value:.2e}");
    }
    if !resolved {
        return format!("{}", (value * 1e4).round() / 1e4 + 0.0);
    }
    let decimals = (-resolution.log10().floor()).clamp(0.0, 6.0) as usize;
    format!("{value:.decimals$}")
}

/// `text` without the trailing zeros of its decimals (and without a trailing point).
fn trim_zeros(text: String) -> String {
    if text.contains('.') && !text.contains('e') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rounds(ticks: &[Tick]) -> Vec<f64> {
        ticks.iter().filter(|t| !t.is_end).map(|t| t.value).collect()
    }

    #[test]
    fn the_ends_are_labelled_and_round_values_lie_between() {
        let ticks = value_ticks(-185.0, 2000.0, 600.0);
        assert_eq!((ticks[0].value, ticks[0].label.as_str(), ticks[0].position), (-185.0, "-185", 0.0));
        assert_eq!((ticks[1].value, ticks[1].label.as_str(), ticks[1].position), (2000.0, "2000", 1.0));
        // 600 points hold six round labels: the step is 500 (2185 / 6 rounds up to 500); 0 would run into "-185"
        // and 2000 is the end.
        assert_eq!(rounds(&ticks), vec![500.0, 1000.0, 1500.0]);
        let middle = ticks.iter().find(|t| t.value == 1000.0).unwrap();
        assert_eq!(middle.label, "1000");
        assert!((middle.position - 1185.0 / 2185.0).abs() < 1e-6);
        // Narrower: fewer, coarser round values.
        assert_eq!(rounds(&value_ticks(-185.0, 2000.0, 320.0)), vec![1000.0]);
    }

    #[test]
    fn labels_never_crowd_each_other_or_the_ends() {
        for &(lo, hi) in &[(0.0, 1.0), (0.0, 65535.0), (-1.0, 1.0), (0.1, 0.30000001), (1e-3, 2e-3), (-3e7, 9e8)] {
            for width in [100.0f32, 200.0, 333.0, 600.0] {
                let ticks = value_ticks(lo, hi, width);
                let mut xs: Vec<f32> = rounds(&ticks).iter().map(|&v| ((v - lo) / (hi - lo)) as f32 * width).collect();
                xs.sort_by(f32::total_cmp);
                for pair in xs.windows(2) {
                    assert!(pair[1] - pair[0] >= LABEL_WIDTH, "{lo}..{hi} at {width}: {ticks:?}");
                }
                for x in xs {
                    assert!(x >= 1.5 * LABEL_WIDTH && width - x >= 1.5 * LABEL_WIDTH, "{lo}..{hi}: {ticks:?}");
                }
                for tick in &ticks {
                    assert!((lo..=hi).contains(&tick.value) && (0.0..=1.0).contains(&tick.position));
                }
            }
        }
    }

    #[test]
    fn round_values_are_multiples_of_one_two_or_five() {
        let ticks = value_ticks(0.0, 1.0, 600.0);
        assert_eq!(rounds(&ticks), vec![0.2, 0.4, 0.6, 0.8]);
        assert_eq!(ticks.iter().map(|t| t.label.as_str()).collect::<Vec<_>>(), ["0", "1", "0.2", "0.4", "0.6", "0.8"]);
        assert_eq!(nice_step(0.13), 0.2);
        assert_eq!(nice_step(3.0), 5.0);
        assert_eq!(nice_step(7.0), 10.0);
        assert_eq!(nice_step(1000.0), 1000.0);
    }

    #[test]
    fn degenerate_ranges_give_few_ticks_and_no_panic() {
        assert!(value_ticks(f64::NAN, 1.0, 300.0).is_empty());
        assert!(value_ticks(0.0, f64::INFINITY, 300.0).is_empty());
        assert!(value_ticks(2.0, 1.0, 300.0).is_empty());
        assert!(value_ticks(0.0, 1.0, 0.0).is_empty());
        let single = value_ticks(5.0, 5.0, 300.0);
        assert_eq!(single.len(), 1);
        assert_eq!(single[0].label, "5");
        // Too narrow for round labels: the ends only.
        assert_eq!(value_ticks(0.0, 100.0, 120.0).len(), 2);
        // A range far from zero at a fine resolution (no endless loop, no lost precision).
        let far = value_ticks(1e15, 1e15 + 10.0, 300.0);
        assert!(far.len() >= 2 && far.iter().all(|t| t.label.contains('e')), "{far:?}");
    }

    #[test]
    fn values_are_written_for_their_resolution() {
        assert_eq!(format_value(1500.0, 500.0), "1500");
        assert_eq!(format_value(0.25, 0.05), "0.25");
        assert_eq!(format_value(-0.0001, 0.01), "0");
        assert_eq!(format_value(-0.5, 0.1), "-0.5");
        assert_eq!(trim_zeros(format_value(12.5, 0.01)), "12.5");
        assert_eq!(format_value(2.5e7, 1e6), "2.50e7");
        assert_eq!(format_value(0.0, 0.0), "0");
        assert_eq!(format_value(1.0 / 3.0, 0.0), "0.3333");
    }
}
