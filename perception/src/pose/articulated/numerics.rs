//! Numerics of the search: row sums of the masks, a symmetric eigensolver, a distance
//! transform, grids.

use workcell_robots::math::Vector;

/// The grid over joints whose values are `axes` (one list per joint, in order): every
/// combination, the last joint varying fastest.
pub(super) fn grid_product(axes: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut grid: Vec<Vec<f64>> = vec![Vec::new()];
    for values in axes {
        grid = grid
            .into_iter()
            .flat_map(|q| {
                values.iter().map(move |x| {
                    let mut v = q.clone();
                    v.push(*x);
                    v
                })
            })
            .collect();
    }
    grid
}

/// Prefix sums of two planes along each row, for sums over row spans of supersampled
/// renders in two lookups a row.
pub(super) struct RowSums {
    pub(super) width: usize,
    /// Per row, `width + 1` pairs: the sums of both planes over the row's first `i` pixels.
    pub(super) prefix: Vec<[f64; 2]>,
}

impl RowSums {
    /// The prefix sums of `a` and `b`, `width` pixels a row.
    pub(super) fn new(a: &[f32], b: &[f32], width: usize) -> Self {
        let mut prefix = Vec::with_capacity(a.len() + a.len() / width.max(1) + 1);
        for (ra, rb) in a
            .chunks_exact(width.max(1))
            .zip(b.chunks_exact(width.max(1)))
        {
            let mut sum = [0.0f64; 2];
            prefix.push(sum);
            for (&x, &y) in ra.iter().zip(rb) {
                sum[0] += f64::from(x);
                sum[1] += f64::from(y);
                prefix.push(sum);
            }
        }
        Self { width, prefix }
    }

    /// Both planes summed over the samples that `spans` cover, in a render of `ss x ss`
    /// samples a pixel (one span per sample row): each pixel's value counted once per
    /// covered sample.
    pub(super) fn over(&self, spans: &[[u32; 2]], ss: usize) -> [f64; 2] {
        let stride = self.width + 1;
        let mut total = [0.0f64; 2];
        for (fy, &[first, last]) in spans.iter().enumerate() {
            if first > last {
                continue;
            }
            let row = &self.prefix[(fy / ss) * stride..(fy / ss + 1) * stride];
            let (a, b) = (first as usize, last as usize);
            let (pa, pb) = (a / ss, b / ss);
            for k in 0..2 {
                let pixel = |i: usize| row[i + 1][k] - row[i][k];
                total[k] += if pa == pb {
                    (b - a + 1) as f64 * pixel(pa)
                } else {
                    // The partly covered pixels at both ends, and the whole ones between.
                    (ss - a % ss) as f64 * pixel(pa)
                        + (b % ss + 1) as f64 * pixel(pb)
                        + ss as f64 * (row[pb][k] - row[pa + 1][k])
                };
            }
        }
        total
    }
}

/// One damped Gauss-Newton step for the variables `free` of `x`: the Jacobian of
/// `residual` by forward differences of `step`, from `r` (the residual at `x`), and the
/// solution of `(J^T J + damping I) dx = -J^T r`, one entry per free variable. `Ok(None)`
/// where that system is singular.
///
/// # Errors
/// `residual`'s.
pub(super) fn gauss_newton_step<const N: usize, E>(
    residual: &mut impl FnMut(&[f64]) -> Result<[f64; N], E>,
    x: &[f64],
    r: &[f64; N],
    free: std::ops::Range<usize>,
    step: f64,
    damping: f64,
) -> Result<Option<Vec<f64>>, E> {
    let n = free.len();
    let mut jacobian = vec![[0.0; N]; n];
    for (column, i) in jacobian.iter_mut().zip(free) {
        let mut v = x.to_vec();
        v[i] += step;
        let rv = residual(&v)?;
        for (c, (a, b)) in column.iter_mut().zip(rv.iter().zip(r)) {
            *c = (a - b) / step;
        }
    }
    let mut normal = vec![vec![0.0; n]; n];
    let mut rhs = vec![0.0; n];
    for i in 0..n {
        for j in 0..n {
            normal[i][j] = (0..N).map(|k| jacobian[i][k] * jacobian[j][k]).sum();
        }
        normal[i][i] += damping;
        rhs[i] = -(0..N).map(|k| jacobian[i][k] * r[k]).sum::<f64>();
    }
    Ok(solve(normal, rhs))
}

/// The mean of `points` and their covariance (divided by their number); `None` for none.
pub(super) fn mean_and_covariance(
    points: impl Iterator<Item = Vector> + Clone,
) -> Option<(Vector, Vec<Vec<f64>>)> {
    let (sum, n) = points
        .clone()
        .fold((Vector::ZERO, 0usize), |(s, n), p| (s + p, n + 1));
    if n == 0 {
        return None;
    }
    let n = n as f64;
    let mean = sum / n;
    let mut covariance = vec![vec![0.0; 3]; 3];
    for p in points {
        let d = p - mean;
        let d = [d.x, d.y, d.z];
        for (i, row) in covariance.iter_mut().enumerate() {
            for (j, c) in row.iter_mut().enumerate() {
                *c += d[i] * d[j] / n;
            }
        }
    }
    Some((mean, covariance))
}

/// The unit eigenvector of a 3x3 covariance's largest eigenvalue (its sign open) and how
/// many times that eigenvalue is the next one (infinite where the next is 0); `None` where
/// the largest is not a positive number.
pub(super) fn principal_axis(covariance: Vec<Vec<f64>>) -> Option<(Vector, f64)> {
    let (values, vectors) = symmetric_eigen(covariance);
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    let largest = values[order[0]];
    if largest.is_nan() || largest <= 0.0 {
        return None;
    }
    let v = &vectors[order[0]];
    let next = values[order[1]].max(0.0);
    let ratio = if next > 0.0 {
        largest / next
    } else {
        f64::INFINITY
    };
    Some((Vector::new(v[0], v[1], v[2]).normalize(), ratio))
}

/// Eigenvalues and unit eigenvectors of a small symmetric matrix (cyclic Jacobi rotations).
pub(super) fn symmetric_eigen(mut a: Vec<Vec<f64>>) -> (Vec<f64>, Vec<Vec<f64>>) {
    let n = a.len();
    let mut v: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| f64::from(u8::from(i == j))).collect())
        .collect();
    for _ in 0..50 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = 0.5 * (2.0 * a[p][q]).atan2(a[q][q] - a[p][p]);
                let (s, c) = theta.sin_cos();
                for row in &mut a {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (row_p, row_q) = (a[p].clone(), a[q].clone());
                a[p] = row_p
                    .iter()
                    .zip(&row_q)
                    .map(|(x, y)| c * x - s * y)
                    .collect();
                a[q] = row_p
                    .iter()
                    .zip(&row_q)
                    .map(|(x, y)| s * x + c * y)
                    .collect();
                for row in &mut v {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let values = (0..n).map(|i| a[i][i]).collect();
    let vectors = (0..n).map(|j| (0..n).map(|i| v[i][j]).collect()).collect();
    (values, vectors)
}

/// Distances in pixels from each pixel to the nearest `inside` one, capped at `cap`
/// (two passes of the 3-4 chamfer metric, within 8 % of the Euclidean distance). All `cap`
/// when nothing is inside.
pub(super) fn distance_transform(inside: &[bool], w: usize, h: usize, cap: f32) -> Vec<f32> {
    let big = cap.max(0.0);
    let mut d: Vec<f32> = inside.iter().map(|&b| if b { 0.0 } else { big }).collect();
    if !inside.iter().any(|&b| b) {
        return d;
    }
    let (a, b) = (1.0f32, std::f32::consts::SQRT_2);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut v = d[i];
            if x > 0 {
                v = v.min(d[i - 1] + a);
            }
            if y > 0 {
                v = v.min(d[i - w] + a);
                if x > 0 {
                    v = v.min(d[i - w - 1] + b);
                }
                if x + 1 < w {
                    v = v.min(d[i - w + 1] + b);
                }
            }
            d[i] = v;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            let mut v = d[i];
            if x + 1 < w {
                v = v.min(d[i + 1] + a);
            }
            if y + 1 < h {
                v = v.min(d[i + w] + a);
                if x + 1 < w {
                    v = v.min(d[i + w + 1] + b);
                }
                if x > 0 {
                    v = v.min(d[i + w - 1] + b);
                }
            }
            d[i] = v.min(big);
        }
    }
    d
}

/// The solution of the small square system `a x = b` (Gaussian elimination with partial
/// pivoting); `None` where `a` is singular to working precision or not square.
pub(super) fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    if a.len() != n || a.iter().any(|row| row.len() != n) {
        return None;
    }
    let scale = a.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()));
    for k in 0..n {
        let pivot = (k..n).max_by(|&i, &j| a[i][k].abs().total_cmp(&a[j][k].abs()))?;
        let magnitude = a[pivot][k].abs();
        if magnitude.is_nan() || magnitude <= 1e-12 * scale {
            return None;
        }
        a.swap(k, pivot);
        b.swap(k, pivot);
        let (above, below) = a.split_at_mut(k + 1);
        let pivot_row = &above[k];
        for (i, row) in below.iter_mut().enumerate() {
            let f = row[k] / pivot_row[k];
            for (x, p) in row[k..].iter_mut().zip(&pivot_row[k..]) {
                *x -= f * p;
            }
            b[k + 1 + i] -= f * b[k];
        }
    }
    let mut x = vec![0.0; n];
    for k in (0..n).rev() {
        let s: f64 = (k + 1..n).map(|j| a[k][j] * x[j]).sum();
        x[k] = (b[k] - s) / a[k][k];
    }
    Some(x)
}
