"""Image quality against the reference: PSNR over RGB and SSIM (Wang et al. 2004) on luma, both on 8-bit images."""
import numpy as np


def psnr(image: np.ndarray, reference: np.ndarray) -> float:
    mse = np.mean((image.astype(np.float64) - reference.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0 ** 2 / mse))


def _gaussian_filter(a: np.ndarray, sigma=1.5, radius=5) -> np.ndarray:
    """Separable Gaussian over the valid region (the usual 11x11 window, no padding)."""
    taps = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma) ** 2)
    taps /= taps.sum()
    n = 2 * radius + 1
    rows = sum(taps[k] * a[:, k:a.shape[1] - n + 1 + k] for k in range(n))
    return sum(taps[k] * rows[k:rows.shape[0] - n + 1 + k, :] for k in range(n))


def luma(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])


def ssim(image: np.ndarray, reference: np.ndarray) -> float:
    x, y = luma(image), luma(reference)
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    mx, my = _gaussian_filter(x), _gaussian_filter(y)
    sxx = _gaussian_filter(x * x) - mx * mx
    syy = _gaussian_filter(y * y) - my * my
    sxy = _gaussian_filter(x * y) - mx * my
    s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))
    return float(s.mean())


if __name__ == "__main__":
    rng = np.random.default_rng(1)
    ramp = np.add.outer(np.linspace(0, 255, 64), np.linspace(0, 255, 64)) / 2
    a = np.stack([ramp] * 3, -1).astype(np.uint8)
    assert psnr(a, a) == float("inf") and abs(ssim(a, a) - 1) < 1e-12
    b = np.clip(a.astype(int) + rng.integers(-20, 21, a.shape), 0, 255).astype(np.uint8)
    assert 20 < psnr(b, a) < 30 and ssim(b, a) < 0.8
    print("metrics self-check ok")
