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
        self.to_bytes::<3>()
    }

    /// 8-bit RGBA: [`Image::to_rgb8`]'s colours and the coverage as alpha.
    pub fn to_rgba8(&self) -> Vec<u8> {
        self.to_bytes::<4>()
    }

    /// The first `C` channels of every pixel as bytes ([`to_u8`]), rows split across the worker threads: a plain
    /// loop over preallocated bytes, which the compiler vectorises (an iterator of per-pixel arrays did not, and
    /// cost 4 ns a pixel).
    fn to_bytes<const C: usize>(&self) -> Vec<u8> {
        use rayon::prelude::*;
        let mut out = vec![0u8; self.pixels.len() * C];
        let row = self.width.max(1) as usize;
        out.par_chunks_mut(row * C).zip(self.pixels.par_chunks(row)).for_each(|(bytes, pixels)| {
            for (byte, pixel) in bytes.chunks_exact_mut(C).zip(pixels) {
                for c in 0..C {
                    byte[c] = to_u8(pixel[c]);
                }
            }
        });
        out
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
    fn bytes_are_each_channel_rounded_and_clamped() {
        let values = [-1.0, 0.0, 0.001, 0.5, 0.998, 1.0, 7.0, f32::NAN, 0.25];
        let mut image = Image::new(7, 5);
        for (n, pixel) in image.pixels.iter_mut().enumerate() {
            *pixel = [0, 1, 2, 3].map(|c| values[(n * 3 + c * 5) % values.len()]);
        }
        let rgb: Vec<u8> = image.pixels.iter().flat_map(|p| [to_u8(p[0]), to_u8(p[1]), to_u8(p[2])]).collect();
        let rgba: Vec<u8> = image.pixels.iter().flat_map(|p| p.map(to_u8)).collect();
        assert_eq!(image.to_rgb8(), rgb);
        assert_eq!(image.to_rgba8(), rgba);
        // (-1, 1, 0, 7) and (0.5, 0.25, 0.998, -1).
        assert_eq!(&rgba[..8], &[0, 255, 0, 255, 128, 64, 254, 0][..]);
    }

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
