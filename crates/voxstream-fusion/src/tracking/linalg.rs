//! The small dense linear algebra tracking needs, which glam lacks: a Cholesky solve of ICP's 6×6 normal equations
//! and Jacobi's eigen-decomposition of small symmetric matrices (the conditioning of those equations; Horn's 4×4
//! matrix of the trajectory alignment).

/// Solves `a x = b` for a symmetric positive definite `a` by Cholesky factorisation `a = L Lᵀ`; `None` when a pivot
/// is not positive (the matrix is singular or indefinite).
#[allow(clippy::needless_range_loop)] // index loops read like the textbook factorisation
pub(crate) fn cholesky_solve<const N: usize>(a: &[[f64; N]; N], b: &[f64; N]) -> Option<[f64; N]> {
    // Factor: the lower triangle of L, column by column.
    let mut l = [[0.0; N]; N];
    for j in 0..N {
        let mut d = a[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        l[j][j] = d.sqrt();
        for i in j + 1..N {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = s / l[j][j];
        }
    }
    // Forward substitution L y = b, then back substitution Lᵀ x = y.
    let mut y = [0.0; N];
    for i in 0..N {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s / l[i][i];
    }
    let mut x = [0.0; N];
    for i in (0..N).rev() {
        let mut s = y[i];
        for k in i + 1..N {
            s -= l[k][i] * x[k];
        }
        x[i] = s / l[i][i];
    }
    Some(x)
}

/// The eigenvalues of a symmetric matrix and its eigenvectors (`vectors[k][i]` is component `k` of the vector of
/// `values[i]`), by cyclic Jacobi rotations; unsorted.
#[allow(clippy::needless_range_loop)] // rotations touch rows and columns by index
pub(crate) fn symmetric_eigen<const N: usize>(mut a: [[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut v = [[0.0; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let total: f64 = a.iter().flatten().map(|x| x * x).sum();
    for _sweep in 0..64 {
        let off: f64 = (0..N).flat_map(|p| (p + 1..N).map(move |q| (p, q))).map(|(p, q)| a[p][q] * a[p][q]).sum();
        if off <= 1e-32 * total || off == 0.0 {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if a[p][q] == 0.0 {
                    continue;
                }
                // The rotation in the (p, q) plane that zeroes a[p][q] (Numerical Recipes §11.1).
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..N {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..N {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for k in 0..N {
                    let (vkp, vkq) = (v[k][p], v[k][q]);
                    v[k][p] = c * vkp - s * vkq;
                    v[k][q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut values = [0.0; N];
    for (i, value) in values.iter_mut().enumerate() {
        *value = a[i][i];
    }
    (values, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed symmetric positive definite 6×6 matrix: Mᵀ M + I for a pseudo-random M.
    fn spd6() -> [[f64; 6]; 6] {
        let m: Vec<f64> = (0..36).map(|i| ((i * 37 % 17) as f64 - 8.0) / 5.0).collect();
        let mut a = [[0.0; 6]; 6];
        for (i, row) in a.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = (0..6).map(|k| m[k * 6 + i] * m[k * 6 + j]).sum::<f64>() + if i == j { 1.0 } else { 0.0 };
            }
        }
        a
    }

    #[test]
    fn cholesky_solves_a_positive_definite_system() {
        let a = spd6();
        let x_true = [0.5, -1.0, 2.0, 0.25, -0.75, 1.5];
        let b: [f64; 6] = std::array::from_fn(|i| (0..6).map(|j| a[i][j] * x_true[j]).sum());
        let x = cholesky_solve(&a, &b).expect("positive definite");
        for (xi, ti) in x.iter().zip(x_true) {
            assert!((xi - ti).abs() < 1e-10, "{x:?}");
        }
        let mut singular = a;
        singular[2] = [0.0; 6];
        for row in singular.iter_mut() {
            row[2] = 0.0;
        }
        assert!(cholesky_solve(&singular, &b).is_none());
    }

    #[test]
    fn jacobi_finds_eigenpairs() {
        let a = spd6();
        let (values, vectors) = symmetric_eigen(a);
        for i in 0..6 {
            let v: [f64; 6] = std::array::from_fn(|k| vectors[k][i]);
            let norm: f64 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!((norm - 1.0).abs() < 1e-12);
            for r in 0..6 {
                let av: f64 = (0..6).map(|c| a[r][c] * v[c]).sum();
                assert!((av - values[i] * v[r]).abs() < 1e-9, "eigenpair {i}: {av} vs {}", values[i] * v[r]);
            }
        }
        let trace: f64 = (0..6).map(|i| a[i][i]).sum();
        assert!((values.iter().sum::<f64>() - trace).abs() < 1e-9);
        assert!(values.iter().all(|&l| l >= 1.0 - 1e-9), "Mᵀ M + I has eigenvalues ≥ 1: {values:?}");
    }
}
