//! ISO 9283:1998 pose accuracy and repeatability, as the SPMS paper tests its ER20-C10 (section
//! 5.3): a cube in the workspace, five points on the diagonal plane C1-C2-C7-C8, n cycles.

use nalgebra::Vector3;

/// Absolute positioning accuracy AP of one point: the distance between the mean of the attained
/// positions and the commanded position, mm (ISO 9283 7.2.1).
pub fn ap(commanded: &Vector3<f64>, attained: &[Vector3<f64>]) -> f64 {
    (mean(attained) - commanded).norm()
}

/// Positioning repeatability RP of one point: `mean(l) + 3 s_l`, `l_j` the distances of the
/// attained positions to their mean and `s_l` their sample standard deviation, mm (ISO 9283 7.2.2).
pub fn rp(attained: &[Vector3<f64>]) -> f64 {
    let m = mean(attained);
    let l: Vec<f64> = attained.iter().map(|p| (p - m).norm()).collect();
    let n = l.len() as f64;
    let lbar = l.iter().sum::<f64>() / n;
    let s = if l.len() > 1 { (l.iter().map(|x| (x - lbar).powi(2)).sum::<f64>() / (n - 1.0)).sqrt() } else { 0.0 };
    lbar + 3.0 * s
}

fn mean(p: &[Vector3<f64>]) -> Vector3<f64> {
    p.iter().sum::<Vector3<f64>>() / p.len() as f64
}

/// The five test points of ISO 9283 on the diagonal plane C1-C2-C7-C8 of a cube of side `side`
/// centred at `centre` (axis-aligned): P1 the centre, P2-P5 on the plane's diagonals at
/// `fraction` (0.1 in the standard) of the diagonal length from the corners C1, C2, C7, C8.
/// The corners of the plane are taken as C1 = (-,-,-), C2 = (+,+,-), C7 = (+,+,+), C8 = (-,-,+)
/// (half sides from the centre): the plane through one bottom edge diagonal and the top one.
pub fn test_points(centre: &Vector3<f64>, side: f64, fraction: f64) -> [Vector3<f64>; 5] {
    let h = side / 2.0;
    let c1 = centre + Vector3::new(-h, -h, -h);
    let c2 = centre + Vector3::new(h, h, -h);
    let c7 = centre + Vector3::new(h, h, h);
    let c8 = centre + Vector3::new(-h, -h, h);
    // P2-P5 lie on the diagonals C1-C7 and C2-C8 of the plane.
    let towards = |from: Vector3<f64>, to: Vector3<f64>| from + (to - from) * fraction;
    [*centre, towards(c1, c7), towards(c2, c8), towards(c7, c1), towards(c8, c2)]
}

/// Statistics over the points of an AP test: max, mean and RMS of the per-point values, mm.
pub fn summary(values: &[f64]) -> (f64, f64, f64) {
    let n = values.len() as f64;
    let max = values.iter().copied().fold(0.0, f64::max);
    let mean = values.iter().sum::<f64>() / n;
    let rms = (values.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    (max, mean, rms)
}
