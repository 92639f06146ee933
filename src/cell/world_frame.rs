//! The world frame {W} from ballbar distances between datum spheres (TriCal paper eqs. 1-5):
//! sphere 1 at the origin, sphere 2 on +x, sphere 3 in the xy-plane with y > 0. With more than
//! three spheres the coordinates are the least-squares fit of all pairwise distances, with the same
//! gauge (Gauss-Newton from the closed form of the first three and a guess for the others).

use nalgebra::{DMatrix, DVector, Vector3};

/// Why sphere coordinates cannot be computed from the distances.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WorldFrameError {
    /// Fewer than three spheres.
    #[error("{0} spheres: at least three define a frame")]
    TooFew(usize),
    /// The first three distances violate the triangle inequality (collinear or inconsistent).
    #[error("spheres 1-3 do not form a triangle (d12 = {d12} mm, d13 = {d13} mm, d23 = {d23} mm)")]
    NotATriangle {
        /// Distance 1-2, mm.
        d12: f64,
        /// Distance 1-3, mm.
        d13: f64,
        /// Distance 2-3, mm.
        d23: f64,
    },
    /// The distances give no finite frame (a non-finite distance, or the fit did not converge).
    #[error("the ballbar distances give no finite frame")]
    NotFinite,
}

/// Sphere centres in {W} from the symmetric matrix of measured centre distances (mm).
/// `guess` (in {W}, any gauge close to the answer) seeds spheres 4 and beyond; it may be empty for three.
pub fn sphere_centres(distances: &DMatrix<f64>, guess: &[Vector3<f64>]) -> Result<Vec<Vector3<f64>>, WorldFrameError> {
    let n = distances.nrows();
    if n < 3 {
        return Err(WorldFrameError::TooFew(n));
    }
    let (d12, d13, d23) = (distances[(0, 1)], distances[(0, 2)], distances[(1, 2)]);
    // Eqs. 4-5.
    let px = (d12 * d12 + d13 * d13 - d23 * d23) / (2.0 * d12);
    let py2 = d13 * d13 - px * px;
    if !(d12 > 0.0 && py2 > 0.0) {
        return Err(WorldFrameError::NotATriangle { d12, d13, d23 });
    }
    let mut p = vec![Vector3::zeros(), Vector3::new(d12, 0.0, 0.0), Vector3::new(px, py2.sqrt(), 0.0)];
    if n == 3 {
        return Ok(p);
    }
    p.extend(guess.iter().skip(3).take(n - 3).copied());
    while p.len() < n {
        p.push(Vector3::new(px, py2.sqrt() / 2.0, 100.0));
    }
    // Unknowns: x2; x3, y3; then x, y, z of each further sphere.
    let unknowns = 3 + 3 * (n - 3);
    let pairs: Vec<(usize, usize)> = (0..n).flat_map(|i| (i + 1..n).map(move |j| (i, j))).collect();
    for _ in 0..50 {
        let mut jac = DMatrix::zeros(pairs.len(), unknowns);
        let mut r = DVector::zeros(pairs.len());
        for (row, &(i, j)) in pairs.iter().enumerate() {
            let diff = p[i] - p[j];
            let d = diff.norm();
            r[row] = distances[(i, j)] - d;
            let u = diff / d;
            for (k, sign) in [(i, 1.0), (j, -1.0)] {
                for (axis, col) in coordinates(k) {
                    jac[(row, col)] += sign * u[axis];
                }
            }
        }
        let step = crate::numeric::svd(jac, true, true).and_then(|s| s.solve(&r, 1e-12).ok()).ok_or(WorldFrameError::NotFinite)?;
        for k in 1..n {
            for (axis, col) in coordinates(k) {
                p[k][axis] += step[col];
            }
        }
        if step.norm() < 1e-12 {
            break;
        }
    }
    Ok(p)
}

/// Free coordinates of sphere k and their columns among the unknowns.
fn coordinates(k: usize) -> Vec<(usize, usize)> {
    match k {
        0 => vec![],
        1 => vec![(0, 0)],
        2 => vec![(0, 1), (1, 2)],
        _ => (0..3).map(|a| (a, 3 + 3 * (k - 3) + a)).collect(),
    }
}

/// The matrix of centre distances of `centres`, mm.
pub fn distance_matrix(centres: &[Vector3<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(centres.len(), centres.len(), |i, j| (centres[i] - centres[j]).norm())
}
