//! The frame buffer: linear RGB plus coverage, and its 8-bit form.

/// A rendered image: linear RGB composited over the background, and the volume's coverage (accumulated opacity).
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major pixels, top row first: `[r, g, b, coverage]`.
    pub pixels: Vec<[f32; 4]>,
}

impl Image {
    /// A black, uncovered image.
    pub fn new(width: u32, height: u32) -> Image {
        Image { width, height, pixels: vec![[0.0; 4]; width as usize * height as usize] }
    }

    /// Pixel `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> [f32; 4] {
        self.pixels[y as usize * self.width as usize + x as usize]
    }

    /// 8-bit RGB, no gamma (VTK's convention: the linear values are written as they are).
    pub fn to_rgb8(&self) -> Vec<u8> {
        self.pixels.iter().flat_map(|p| [to_u8(p[0]), to_u8(p[1]), to_u8(p[2])]).collect()
    }

    /// 8-bit RGBA: [`Image::to_rgb8`]'s colours and the coverage as alpha.
    pub fn to_rgba8(&self) -> Vec<u8> {
        self.pixels.iter().flat_map(|p| p.map(to_u8)).collect()
    }
}

/// Quantises a linear value in `[0, 1]` to 8 bits, rounding to nearest.
#[inline]
pub fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Peak signal-to-noise ratio (dB) between two 8-bit images of the same size; infinite when equal.
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len(), "psnr needs images of the same size");
    let mse = a.iter().zip(b).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum::<f64>() / a.len().max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_of_known_error() {
        let a = vec![0u8; 100];
        let mut b = a.clone();
        assert!(psnr(&a, &b).is_infinite());
        b[0] = 255; // mse = 255²/100
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-9);
    }

    #[test]
    fn rounding_is_to_nearest() {
        assert_eq!(to_u8(0.5), 128);
        assert_eq!(to_u8(-1.0), 0);
        assert_eq!(to_u8(2.0), 255);
    }
}
