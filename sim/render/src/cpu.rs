//! The software rasterizer.

use rayon::prelude::*;
use workcell_robots::math::Pose;

use crate::error::{RenderError, Result};
use crate::{
    Camera, Frame, MaskBatch, NEAR_M, RenderMesh, Renderer, SUBPIXEL_BITS, Scene, SpanBatch,
    pose_is_finite,
};

const SUB: i64 = 1 << SUBPIXEL_BITS;
/// Triangles are clipped to this many pixels beyond the image, so that fixed-point edge
/// functions stay far from overflow; a GPU's guard band plays the same role.
const GUARD_PX: f32 = 8192.0;

/// The software rasterizer: single-threaded per image, masks of a batch in parallel (rayon).
/// It keeps its buffers between calls, and what [`Renderer::render`] needs to draw the next
/// frame of the same view faster ([`FrameCache`]).
#[derive(Debug, Clone, Default)]
pub struct CpuRenderer {
    vertices: Vec<[f32; 3]>,
    inv_z: Vec<f32>,
    color: Vec<[f32; 3]>,
    cache: FrameCache,
    scratch: SpanScratch,
}

/// What a frame leaves for the next one of the same camera and light, so that a camera
/// watching a cell redraws only what moved, with the same image to the bit:
///
/// - **the drawn prefix**: the z-buffer, object index and colour after the scene's first
///   objects that have not moved since the frame before (the room, the table, the clutter:
///   the scene lists them first). Objects are drawn in order and the depth test keeps the
///   first of equal depths, so the state after the same objects at the same poses is the
///   same; the next frame starts from it and draws the rest.
/// - **the resolve**: each pixel's texture, sRGB and depth follow from its object, colour
///   and 1/z alone (the camera, sky and textures being the same): a pixel whose three are
///   those of the frame before keeps its output.
#[derive(Debug, Clone, Default)]
struct FrameCache {
    /// The camera and light the buffers below were drawn with.
    view: Option<(Camera, [f32; 3])>,
    /// The last frame's objects: each mesh (held, so that its address names it) and pose.
    objects: Vec<(std::sync::Arc<RenderMesh>, Pose)>,
    /// How many of the scene's first objects the prefix buffers hold.
    drawn: usize,
    inv_z: Vec<f32>,
    object: Vec<u16>,
    color: Vec<[f32; 3]>,
    /// The sky and each object's texture amplitude the last resolve used (with `view`'s
    /// camera; none after the view changed).
    resolved_with: Option<([f32; 3], Vec<f32>)>,
    /// The last resolve's inputs and outputs per pixel (a pixel resolved anew writes its
    /// own; a kept one has them already).
    last_object: Vec<u16>,
    last_inv_z: Vec<f32>,
    last_color: Vec<[f32; 3]>,
    last_rgb: Vec<u8>,
    last_depth: Vec<f32>,
}

impl CpuRenderer {
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }
}

/// A pose as a 3x4 matrix in f32, rows of `[R | t]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Affine(pub(crate) [[f32; 4]; 3]);

impl Affine {
    pub(crate) fn from_pose(X: &Pose) -> Self {
        let m = parry3d_f64::glamx::DMat3::from_quat(X.rotation);
        let t = X.translation;
        let row = |r: usize| {
            let v = m.row(r);
            [v.x as f32, v.y as f32, v.z as f32, t[r] as f32]
        };
        Self([row(0), row(1), row(2)])
    }

    #[inline]
    pub(crate) fn apply(&self, p: [f32; 3]) -> [f32; 3] {
        let m = &self.0;
        [0, 1, 2].map(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3])
    }

    #[inline]
    pub(crate) fn rotate(&self, p: [f32; 3]) -> [f32; 3] {
        let m = &self.0;
        [0, 1, 2].map(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2])
    }
}

#[inline]
pub(crate) fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub(crate) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub(crate) fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Pinhole intrinsics in f32 and the clip planes of the image.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Projection {
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    width: u32,
    height: u32,
    /// Planes `n . p + d >= 0` (camera frame) a visible point satisfies: near, then the
    /// guard band's left, right, top, bottom.
    planes: [([f32; 3], f32); 5],
}

/// A vertex as the rasterizer takes it ([`Projection::snap`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Snapped {
    x: i64,
    y: i64,
    iz: f32,
}

/// One image row's run of pixel centres that a triangle covers, `first..=last`, with the
/// triangle's edge functions at `first` and their step per pixel (for interpolation).
pub(crate) struct RowSpan {
    pub(crate) row: usize,
    /// The row's first pixel's index in the image.
    pub(crate) base: usize,
    pub(crate) first: usize,
    pub(crate) last: usize,
    pub(crate) e: [i64; 3],
    pub(crate) step: [i64; 3],
    /// `1/z` at each vertex over twice the area: `E_1 w_0 + E_2 w_1 + E_0 w_2` is `1/z`.
    pub(crate) w: [f32; 3],
}

impl RowSpan {
    /// Calls `pixel(index, 1/z)` for each of the run's pixels, `1/z` interpolated as the
    /// edge functions step.
    #[inline]
    pub(crate) fn pixels(&self, mut pixel: impl FnMut(usize, f32)) {
        let mut e = self.e;
        for i in self.first..=self.last {
            debug_assert!((e[0] | e[1] | e[2]) >= 0, "a pixel outside the span");
            let z = e[1] as f32 * self.w[0] + e[2] as f32 * self.w[1] + e[0] as f32 * self.w[2];
            pixel(self.base + i, z);
            for (e, step) in e.iter_mut().zip(self.step) {
                *e += step;
            }
        }
    }
}

impl Projection {
    pub(crate) fn new(c: &Camera) -> Self {
        let (fx, fy, cx, cy) = (c.fx as f32, c.fy as f32, c.cx as f32, c.cy as f32);
        let (w, h) = (c.width as f32, c.height as f32);
        // u >= -G  <=>  fx x + (cx + G) z >= 0;  u <= w + G  <=>  -fx x + (w + G - cx) z >= 0.
        let planes = [
            ([0.0, 0.0, 1.0], -(NEAR_M as f32)),
            ([fx, 0.0, cx + GUARD_PX], 0.0),
            ([-fx, 0.0, w + GUARD_PX - cx], 0.0),
            ([0.0, fy, cy + GUARD_PX], 0.0),
            ([0.0, -fy, h + GUARD_PX - cy], 0.0),
        ];
        Self {
            fx,
            fy,
            cx,
            cy,
            width: c.width,
            height: c.height,
            planes,
        }
    }

    /// Clips triangle `(a, b, c)` (camera frame) to the view and rasterizes the pieces,
    /// calling `pixel(index, 1/z)` for every covered pixel centre.
    #[inline]
    pub(crate) fn triangle(&self, t: [[f32; 3]; 3], pixel: &mut impl FnMut(usize, f32)) {
        self.triangle_rows(t, &mut |span: &RowSpan| span.pixels(&mut *pixel));
    }

    /// Clips triangle `(a, b, c)` (camera frame) to the view and calls `row` with each
    /// image row's run of covered pixel centres (the same pixels as [`Projection::triangle`]).
    #[inline]
    pub(crate) fn triangle_rows(&self, t: [[f32; 3]; 3], row: &mut impl FnMut(&RowSpan)) {
        if t.iter().all(|&p| self.inside(p)) {
            self.raster(t, row);
            return;
        }
        // Sutherland-Hodgman against each plane; a triangle gains at most one vertex per plane.
        let mut poly = [[0.0f32; 3]; 8];
        let mut next = [[0.0f32; 3]; 8];
        poly[..3].copy_from_slice(&t);
        let mut n = 3;
        for &(normal, d) in &self.planes {
            let mut m = 0;
            for i in 0..n {
                let (p, q) = (poly[i], poly[(i + 1) % n]);
                let (dp, dq) = (dot(normal, p) + d, dot(normal, q) + d);
                if dp >= 0.0 {
                    next[m] = p;
                    m += 1;
                }
                if (dp >= 0.0) != (dq >= 0.0) {
                    let s = dp / (dp - dq);
                    next[m] = [0, 1, 2].map(|k| p[k] + s * (q[k] - p[k]));
                    m += 1;
                }
            }
            std::mem::swap(&mut poly, &mut next);
            n = m;
            if n < 3 {
                return;
            }
        }
        for i in 1..n - 1 {
            self.raster([poly[0], poly[i], poly[i + 1]], row);
        }
    }

    /// Rasterizes a triangle in front of the near plane: vertices snapped to 1/256 px,
    /// integer edge functions, top-left rule for pixel centres on an edge; `row` gets each
    /// row's run of covered pixels.
    #[inline]
    fn raster(&self, t: [[f32; 3]; 3], row_span: &mut impl FnMut(&RowSpan)) {
        self.raster_snapped(t.map(|p| self.snap(p)), row_span);
    }

    /// A camera-frame point in front of the near plane as the rasterizer takes it: its
    /// image position in 1/256 px, and `1/z`.
    #[inline]
    pub(crate) fn snap(&self, [px, py, pz]: [f32; 3]) -> Snapped {
        let iz = 1.0 / pz;
        Snapped {
            x: round_to_int((self.fx * px * iz + self.cx) * SUB as f32),
            y: round_to_int((self.fy * py * iz + self.cy) * SUB as f32),
            iz,
        }
    }

    /// Whether a camera-frame point is inside every clip plane: a triangle of three such
    /// points is rasterized unclipped.
    #[inline]
    pub(crate) fn inside(&self, p: [f32; 3]) -> bool {
        self.planes.iter().all(|&(n, d)| dot(n, p) + d >= 0.0)
    }

    /// [`Projection::raster`] of a triangle whose vertices are snapped already.
    #[inline]
    pub(crate) fn raster_snapped(&self, v: [Snapped; 3], row_span: &mut impl FnMut(&RowSpan)) {
        let mut x = v.map(|v| v.x);
        let mut y = v.map(|v| v.y);
        let mut iz = v.map(|v| v.iz);
        let mut area = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]);
        if area == 0 {
            return;
        }
        if area < 0 {
            x.swap(1, 2);
            y.swap(1, 2);
            iz.swap(1, 2);
            area = -area;
        }
        let (w, h) = (i64::from(self.width), i64::from(self.height));
        // Pixel i's centre is at i * SUB + SUB / 2.
        let first = |lo: i64| (lo - SUB / 2 + SUB - 1).div_euclid(SUB).max(0);
        let last = |hi: i64, n: i64| (hi - SUB / 2).div_euclid(SUB).min(n - 1);
        let (i0, i1) = (
            first(*x.iter().min().unwrap_or(&0)),
            last(*x.iter().max().unwrap_or(&0), w),
        );
        let (j0, j1) = (
            first(*y.iter().min().unwrap_or(&0)),
            last(*y.iter().max().unwrap_or(&0), h),
        );
        if i0 > i1 || j0 > j1 {
            return;
        }
        // Edge k runs from vertex k to k+1; E_k(p) = dx (p.y - a.y) - dy (p.x - a.x) >= 0
        // inside. Its weight goes to the vertex opposite.
        let mut step_x = [0i64; 3];
        let mut step_y = [0i64; 3];
        let mut row = [0i64; 3];
        let (px0, py0) = (i0 * SUB + SUB / 2, j0 * SUB + SUB / 2);
        for k in 0..3 {
            let (a, b) = (k, (k + 1) % 3);
            let (dx, dy) = (x[b] - x[a], y[b] - y[a]);
            let top_left = dy < 0 || (dy == 0 && dx > 0);
            row[k] = dx * (py0 - y[a]) - dy * (px0 - x[a]) - i64::from(!top_left);
            step_x[k] = -dy * SUB;
            step_y[k] = dx * SUB;
        }
        let inv_area = 1.0 / area as f32;
        // Weights: E_1 (edge b-c) for vertex a, E_2 for b, E_0 for c.
        let (wa, wb, wc) = (iz[0] * inv_area, iz[1] * inv_area, iz[2] * inv_area);
        let stride = self.width as usize;
        // The row's span: E_k(i0 + t) = row_k + t step_k >= 0 for every edge, solved for t
        // exactly in integers (the same pixels as testing each one of the bounding box): a
        // floor division by the edge's step, carried from row to row without dividing.
        let mut bounds = [0, 1, 2].map(|k| {
            let (r, s, dr) = (row[k], step_x[k], step_y[k]);
            match s.cmp(&0) {
                // t >= ceil(-r / s) = floor((s - 1 - r) / s).
                std::cmp::Ordering::Greater => Some((true, RowFloor::new(s - 1 - r, -dr, s))),
                // t <= floor(r / -s).
                std::cmp::Ordering::Less => Some((false, RowFloor::new(r, dr, -s))),
                std::cmp::Ordering::Equal => None,
            }
        });
        for j in j0..=j1 {
            let (mut lo, mut hi) = (0i64, i1 - i0);
            for (k, bound) in bounds.iter_mut().enumerate() {
                match bound {
                    Some((true, b)) => lo = lo.max(b.next()),
                    Some((false, b)) => hi = hi.min(b.next()),
                    None if row[k] < 0 => hi = -1,
                    None => {}
                }
            }
            if lo <= hi {
                row_span(&RowSpan {
                    row: j as usize,
                    base: j as usize * stride,
                    first: (i0 + lo) as usize,
                    last: (i0 + hi) as usize,
                    e: [0, 1, 2].map(|k| row[k] + lo * step_x[k]),
                    step: step_x,
                    w: [wa, wb, wc],
                });
            }
            row[0] += step_y[0];
            row[1] += step_y[1];
            row[2] += step_y[2];
        }
    }
}

impl Projection {
    /// `mesh`'s vertices at `X_CO` snapped into `points` (x and y as [`Projection::snap`]
    /// gives them, packed by [`pack_point`]) where every one is finite and inside the view;
    /// false where one is not.
    #[inline]
    pub(crate) fn snap_points(
        &self,
        mesh: &RenderMesh,
        X_CO: &Affine,
        points: &mut Vec<u64>,
    ) -> bool {
        points.clear();
        points.reserve(mesh.positions.len());
        // No early exit, and the snapping in 32-bit lanes, so that the loop vectorizes:
        // inside the guard band a snapped coordinate is below 2^31 and `round_to_int`'s.
        let mut inside = true;
        for &p in &mesh.positions {
            let p = X_CO.apply(p);
            inside &= p[0].is_finite() & p[1].is_finite() & p[2].is_finite() & self.inside(p);
            let iz = 1.0 / p[2];
            let x = round_to_i32((self.fx * p[0] * iz + self.cx) * SUB as f32);
            let y = round_to_i32((self.fy * p[1] * iz + self.cy) * SUB as f32);
            points.push(pack_point(x, y));
        }
        inside
    }

    /// The rows of the convex polygon around `points` (snapped vertices packed by
    /// [`pack_point`], sorted and deduplicated in place), as [`Projection::raster_snapped`] covers the triangles that
    /// tile it: `row(j, first, last)` for each image row `j` whose pixel centres
    /// `first..=last` it covers, by the same edge functions and the same top-left rule on
    /// the polygon's edges. Nothing where the points span no area.
    ///
    /// The polygon's two chains from its first vertex to its last in `(y, x)` order are
    /// built in `chains` (Andrew's monotone chain, collinear points dropped): the left
    /// chain's edges bound each row from below, the right chain's from above. Each edge's
    /// bound is carried from row to row ([`RowFloor`]).
    pub(crate) fn convex_rows(
        &self,
        points: &mut Vec<u64>,
        chains: &mut [Vec<[i64; 2]>; 2],
        mut row: impl FnMut(usize, usize, usize),
    ) {
        points.sort_unstable();
        points.dedup();
        let cross = |o: [i64; 2], a: [i64; 2], b: [i64; 2]| {
            (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
        };
        let [left, right] = chains;
        left.clear();
        right.clear();
        for p in points.iter().map(|&p| unpack_point(p)) {
            while left.len() >= 2 && cross(left[left.len() - 2], left[left.len() - 1], p) >= 0 {
                left.pop();
            }
            left.push(p);
            while right.len() >= 2 && cross(right[right.len() - 2], right[right.len() - 1], p) <= 0
            {
                right.pop();
            }
            right.push(p);
        }
        let (Some(top), Some(bottom)) = (left.first(), left.last()) else {
            return;
        };
        if left.len() + right.len() < 5 {
            // Both chains are the segment from the top to the bottom (or a point): no area.
            return;
        }
        let (w, h) = (i64::from(self.width), i64::from(self.height));
        let first = |lo: i64| (lo - SUB / 2 + SUB - 1).div_euclid(SUB).max(0);
        let last = |hi: i64, n: i64| (hi - SUB / 2).div_euclid(SUB).min(n - 1);
        let (j0, j1) = (first(top[1]), last(bottom[1], h));
        let mut sides = [
            ChainBound::new(left, true, j0),
            ChainBound::new(right, false, j0),
        ];
        for j in j0..=j1 {
            let (mut lo, mut hi) = (0, w - 1);
            for side in &mut sides {
                side.bound(&mut lo, &mut hi);
            }
            if lo <= hi {
                row(j as usize, lo as usize, hi as usize);
            }
        }
    }
}

/// One chain of [`Projection::convex_rows`]'s polygon walked down row by row: the edge that
/// crosses the row and its bound on the row's pixels, carried from row to row.
struct ChainBound<'a> {
    /// The chain's vertices by y.
    chain: &'a [[i64; 2]],
    /// The left chain's edges are oriented upward, the right chain's downward: the
    /// polygon's inside is where an edge function is not negative.
    upward: bool,
    /// The edge (from `chain[at]` to `chain[at + 1]`) whose bound `floor` carries, once
    /// a row has read it.
    at: usize,
    floor: Option<(bool, RowFloor)>,
    /// The row [`ChainBound::bound`] narrows next.
    row: i64,
}

impl<'a> ChainBound<'a> {
    fn new(chain: &'a [[i64; 2]], upward: bool, row: i64) -> Self {
        Self {
            chain,
            upward,
            at: 0,
            floor: None,
            row,
        }
    }

    /// Edge `k`'s bound on row `j`'s pixel indices, carried to the rows after: `(true, _)`
    /// bounds them from below, `(false, _)` from above. A horizontal edge has none: `Err`
    /// with whether it leaves no pixel of the row.
    fn edge(&self, k: usize, j: i64) -> Result<(bool, RowFloor), bool> {
        let (a, b) = if self.upward {
            (self.chain[k + 1], self.chain[k])
        } else {
            (self.chain[k], self.chain[k + 1])
        };
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let top_left = dy < 0 || (dy == 0 && dx > 0);
        // E(i) = dx (yc - a.y) - dy (i SUB + SUB/2 - a.x) - bias = r + s i, yc = j SUB + SUB/2.
        let yc = j * SUB + SUB / 2;
        let r = dx * (yc - a[1]) - dy * (SUB / 2 - a[0]) - i64::from(!top_left);
        let s = -dy * SUB;
        let dr = dx * SUB;
        match s.cmp(&0) {
            // i >= ceil(-r / s) = floor((s - 1 - r) / s).
            std::cmp::Ordering::Greater => Ok((true, RowFloor::new(s - 1 - r, -dr, s))),
            // i <= floor(r / -s).
            std::cmp::Ordering::Less => Ok((false, RowFloor::new(r, dr, -s))),
            std::cmp::Ordering::Equal => Err(r < 0),
        }
    }

    /// Narrows `lo..=hi` to the pixels of the next row (the first, then the one after the
    /// last call's) inside every edge of the chain that the row's centre crosses.
    fn bound(&mut self, lo: &mut i64, hi: &mut i64) {
        let j = self.row;
        self.row += 1;
        let yc = j * SUB + SUB / 2;
        let chain = self.chain;
        let apply = |(lower, mut f): (bool, RowFloor), lo: &mut i64, hi: &mut i64| {
            let n = f.next();
            if lower {
                *lo = (*lo).max(n);
            } else {
                *hi = (*hi).min(n);
            }
            f
        };
        // The first edge that reaches down to the row.
        let mut k = self.at;
        while k + 2 < chain.len() && chain[k + 1][1] < yc {
            k += 1;
        }
        if k != self.at {
            self.at = k;
            self.floor = None;
        }
        if chain[k][1].min(chain[k + 1][1]) <= yc {
            match self.floor {
                Some(f) => self.floor = Some((f.0, apply(f, lo, hi))),
                None => match self.edge(k, j) {
                    Ok(f) => self.floor = Some((f.0, apply(f, lo, hi))),
                    Err(true) => *hi = -1,
                    Err(false) => {}
                },
            }
        } else {
            self.floor = None;
        }
        // Further edges through the row: it passes a vertex exactly, or runs along a
        // horizontal edge. Rare; their bound is not carried.
        let mut k = k + 1;
        while k + 1 < chain.len() && chain[k][1] <= yc {
            if chain[k + 1][1] >= yc {
                match self.edge(k, j) {
                    Ok(f) => {
                        apply(f, lo, hi);
                    }
                    Err(true) => *hi = -1,
                    Err(false) => {}
                }
            }
            k += 1;
        }
    }
}

/// `floor(n / d)` for `n` growing by `dn` a row (`d > 0`), one row after another: the
/// quotient and the remainder carried, two divisions in all.
#[derive(Debug, Clone, Copy)]
struct RowFloor {
    q: i64,
    m: i64,
    dq: i64,
    dm: i64,
    d: i64,
}

impl RowFloor {
    #[inline]
    fn new(n: i64, dn: i64, d: i64) -> Self {
        Self {
            q: n.div_euclid(d),
            m: n.rem_euclid(d),
            dq: dn.div_euclid(d),
            dm: dn.rem_euclid(d),
            d,
        }
    }

    /// This row's `floor(n / d)`; then steps to the next row.
    #[inline]
    fn next(&mut self) -> i64 {
        let q = self.q;
        self.q += self.dq;
        self.m += self.dm;
        if self.m >= self.d {
            self.m -= self.d;
            self.q += 1;
        }
        q
    }
}

/// `v.floor() as i32` without the library call that `floor` is on CPUs before SSE4.1 (the
/// baseline x86-64 target): the texture takes three a pixel. The same value for every `v`
/// (saturating like `as`; NaN is 0).
#[inline]
pub(crate) fn floor_to_int(v: f32) -> i32 {
    let i = v as i32;
    if (i as f32) > v {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// `v.round() as i64` (half away from zero) without the library call, as [`floor_to_int`]:
/// the rasterizer snaps six coordinates a triangle.
#[inline]
pub(crate) fn round_to_int(v: f32) -> i64 {
    let i = v as i64;
    // Exact: below 2^23 the fraction is representable, above it every f32 is an integer.
    let f = v - i as f32;
    if f >= 0.5 {
        i.saturating_add(1)
    } else if f <= -0.5 {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// A snapped point as one key whose order is the `(y, x)` order (each offset by 2^31).
#[inline]
pub(crate) fn pack_point(x: i32, y: i32) -> u64 {
    let offset = |v: i32| u64::from(v.wrapping_sub(i32::MIN) as u32);
    (offset(y) << 32) | offset(x)
}

/// The `[x, y]` of [`pack_point`]'s key.
#[inline]
pub(crate) fn unpack_point(key: u64) -> [i64; 2] {
    let back = |v: u64| i64::from((v as u32).wrapping_add(i32::MIN as u32) as i32);
    [back(key), back(key >> 32)]
}

/// [`round_to_int`] in 32 bits, for `|v| < 2^31` (larger values saturate): branch-free, so
/// that a loop of them vectorizes.
#[inline]
pub(crate) fn round_to_i32(v: f32) -> i32 {
    let i = v as i32;
    // Exact: below 2^23 the fraction is representable, above it every f32 is an integer.
    let f = v - i as f32;
    i.saturating_add(i32::from(f >= 0.5))
        .saturating_sub(i32::from(f <= -0.5))
}

/// A hash of an integer lattice point to [0, 1), the texture's value noise.
#[inline]
pub(crate) fn lattice_noise(x: i32, y: i32, z: i32) -> f32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841)
        ^ (z as u32).wrapping_mul(0xcb1a_b31f);
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0xffff) as f32 / 65536.0
}

/// Texture factor at world point `p`: two octaves of value noise (3 cm and 15 cm cells).
#[inline]
pub(crate) fn texture_factor(p: [f32; 3], amplitude: f32) -> f32 {
    let cell = |s: f32| {
        let q = p.map(|v| floor_to_int(v / s));
        lattice_noise(q[0], q[1], q[2])
    };
    let n = 0.6 * cell(0.03) + 0.4 * cell(0.15);
    1.0 + amplitude * (n - 0.5) * 2.0
}

/// Flat shading of a face with camera-frame normal `n` (any length) and first vertex `a`:
/// ambient, the directional light and a headlight, on both sides of the face.
#[inline]
pub(crate) fn shade(n: [f32; 3], a: [f32; 3], light_C: [f32; 3]) -> f32 {
    let len = dot(n, n).sqrt();
    if len <= 0.0 {
        return 0.25;
    }
    let mut nn = n.map(|v| v / len);
    if dot(nn, a) > 0.0 {
        nn = nn.map(|v| -v);
    }
    let view = dot(a, a).sqrt().max(1e-12);
    let head = (-dot(nn, a) / view).max(0.0);
    0.25 + 0.55 * dot(nn, light_C).max(0.0) + 0.25 * head
}

/// Linear [0, 1] to sRGB bytes.
fn srgb_table() -> &'static [u8; 4096] {
    static TABLE: std::sync::OnceLock<[u8; 4096]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|i| {
            let l = i as f64 / 4095.0;
            let s = if l <= 0.003_130_8 {
                12.92 * l
            } else {
                1.055 * l.powf(1.0 / 2.4) - 0.055
            };
            (s * 255.0).round() as u8
        })
    })
}

#[inline]
pub(crate) fn to_srgb(table: &[u8; 4096], l: f32) -> u8 {
    table[((l.clamp(0.0, 1.0) * 4095.0) as usize).min(4095)]
}

/// The buffers a shaded render draws into: 1/z, object index and linear colour per pixel.
struct Shaded<'a> {
    inv_z: &'a mut Vec<f32>,
    object: &'a mut Vec<u16>,
    color: &'a mut Vec<[f32; 3]>,
}

impl Shaded<'_> {
    /// Draws `object`, the scene's `k`-th, where it is nearer than what is drawn.
    fn draw(
        &mut self,
        proj: &Projection,
        X_CW: &Pose,
        light_C: [f32; 3],
        k: usize,
        object: &crate::SceneObject,
        vertices: &mut Vec<[f32; 3]>,
    ) {
        let X_CO = Affine::from_pose(&(*X_CW * object.X_WO));
        let id = (k + 1) as u16;
        let Self {
            inv_z,
            object: ids,
            color,
        } = self;
        front_faces(&object.mesh, &X_CO, vertices, |t, n, albedo| {
            let s = shade(n, t[0], light_C);
            let c = albedo.map(|a| a * s);
            proj.triangle(t, &mut |p, z| {
                if z > inv_z[p] {
                    inv_z[p] = z;
                    ids[p] = id;
                    color[p] = c;
                }
            });
        });
    }
}

/// Checks the poses of a scene's objects.
pub(crate) fn check_scene(scene: &Scene) -> Result<()> {
    if scene.objects.len() >= usize::from(u16::MAX) {
        return Err(RenderError::InvalidRender {
            message: format!(
                "{} objects; at most {} can be indexed",
                scene.objects.len(),
                u16::MAX - 1
            ),
        });
    }
    match scene.objects.iter().find(|o| !pose_is_finite(&o.X_WO)) {
        Some(o) => Err(RenderError::InvalidRender {
            message: format!("object {} has a pose that is not finite", o.name),
        }),
        None => Ok(()),
    }
}

/// Checks the poses of a mask batch.
pub(crate) fn check_poses(X_CO: &[Pose]) -> Result<()> {
    match X_CO.iter().position(|X| !pose_is_finite(X)) {
        Some(k) => Err(RenderError::InvalidRender {
            message: format!("mask pose {k} is not finite"),
        }),
        None => Ok(()),
    }
}

impl Renderer for CpuRenderer {
    fn name(&self) -> String {
        "cpu".into()
    }

    fn render(&mut self, scene: &Scene, camera: &Camera, frame: &mut Frame) -> Result<()> {
        camera.validate()?;
        check_scene(scene)?;
        let proj = Projection::new(camera);
        let n = camera.width as usize * camera.height as usize;
        frame.resize(camera.width, camera.height);
        self.inv_z.resize(n, 0.0);
        self.color.resize(n, [0.0; 3]);
        let X_CW = camera.X_WC.inverse();
        let light_C = Affine::from_pose(&X_CW).rotate(scene.light_W);
        let Self {
            vertices,
            inv_z,
            color,
            cache,
            ..
        } = self;
        // The objects unchanged since the last frame of this view, and where to start.
        let view = Some((*camera, scene.light_W));
        if cache.view != view {
            cache.drawn = 0;
            cache.objects.clear();
            // A pixel's texture and depth follow from where the camera puts it, too.
            cache.resolved_with = None;
        }
        let unchanged = scene
            .objects
            .iter()
            .zip(&cache.objects)
            .take_while(|(o, (mesh, X_WO))| {
                std::sync::Arc::ptr_eq(&o.mesh, mesh) && o.X_WO == *X_WO
            })
            .count();
        let mut start = 0;
        if cache.drawn > 0 && cache.drawn <= unchanged {
            inv_z.copy_from_slice(&cache.inv_z);
            frame.object.copy_from_slice(&cache.object);
            color.copy_from_slice(&cache.color);
            start = cache.drawn;
        } else {
            inv_z.fill(0.0);
            frame.object.fill(0);
        }
        let mut buffers = Shaded {
            inv_z,
            object: &mut frame.object,
            color,
        };
        for (k, object) in scene.objects.iter().enumerate().take(unchanged).skip(start) {
            buffers.draw(&proj, &X_CW, light_C, k, object, vertices);
        }
        if unchanged > start {
            cache.inv_z.clone_from(buffers.inv_z);
            cache.object.clone_from(buffers.object);
            cache.color.clone_from(buffers.color);
            cache.drawn = unchanged;
        }
        for (k, object) in scene.objects.iter().enumerate().skip(unchanged.max(start)) {
            buffers.draw(&proj, &X_CW, light_C, k, object, vertices);
        }
        cache.view = view;
        // The first `unchanged` are the scene's already.
        cache.objects.truncate(unchanged);
        cache.objects.extend(
            scene.objects[unchanged..]
                .iter()
                .map(|o| (o.mesh.clone(), o.X_WO)),
        );
        // Resolve: texture, sRGB, depth; a pixel as the last frame's keeps its output, and
        // one resolved anew is written to the cache as well.
        let reuse = cache.resolved_with.as_ref().is_some_and(|(sky, t)| {
            *sky == scene.sky
                && t.len() == scene.objects.len()
                && t.iter().zip(&scene.objects).all(|(a, o)| *a == o.texture)
        }) && cache.last_object.len() == n;
        if !reuse {
            // Every pixel is resolved anew below and overwrites these.
            cache.last_object.resize(n, 0);
            cache.last_inv_z.resize(n, 0.0);
            cache.last_color.resize(n, [0.0; 3]);
            cache.last_rgb.resize(3 * n, 0);
            cache.last_depth.resize(n, 0.0);
        }
        let table = srgb_table();
        let X_WC = Affine::from_pose(&camera.X_WC);
        let (fx, fy, cx, cy) = (proj.fx, proj.fy, proj.cx, proj.cy);
        let w = camera.width as usize;
        for p in 0..n {
            let id = frame.object[p];
            if reuse
                && cache.last_object[p] == id
                && cache.last_inv_z[p].to_bits() == inv_z[p].to_bits()
                && cache.last_color[p].map(f32::to_bits) == color[p].map(f32::to_bits)
            {
                frame.depth_m[p] = cache.last_depth[p];
                frame.rgb[3 * p..3 * p + 3].copy_from_slice(&cache.last_rgb[3 * p..3 * p + 3]);
                continue;
            }
            let (c, depth) = if id == 0 {
                (scene.sky, 0.0)
            } else {
                let z = 1.0 / inv_z[p];
                let amplitude = scene.objects[usize::from(id) - 1].texture;
                let mut c = color[p];
                if amplitude > 0.0 {
                    let (i, j) = ((p % w) as f32 + 0.5, (p / w) as f32 + 0.5);
                    let p_W = X_WC.apply([(i - cx) / fx * z, (j - cy) / fy * z, z]);
                    let f = texture_factor(p_W, amplitude);
                    c = c.map(|v| v * f);
                }
                (c, z)
            };
            frame.depth_m[p] = depth;
            for (out, v) in frame.rgb[3 * p..3 * p + 3].iter_mut().zip(c) {
                *out = to_srgb(table, v);
            }
            cache.last_object[p] = id;
            cache.last_inv_z[p] = inv_z[p];
            cache.last_color[p] = color[p];
            cache.last_depth[p] = depth;
            cache.last_rgb[3 * p..3 * p + 3].copy_from_slice(&frame.rgb[3 * p..3 * p + 3]);
        }
        let (sky, textures) = cache.resolved_with.get_or_insert_with(Default::default);
        *sky = scene.sky;
        textures.clear();
        textures.extend(scene.objects.iter().map(|o| o.texture));
        Ok(())
    }

    fn render_depth(
        &mut self,
        scene: &Scene,
        camera: &Camera,
        depth_m: &mut Vec<f32>,
    ) -> Result<()> {
        camera.validate()?;
        check_scene(scene)?;
        let proj = Projection::new(camera);
        let n = camera.width as usize * camera.height as usize;
        self.inv_z.clear();
        self.inv_z.resize(n, 0.0);
        let X_CW = camera.X_WC.inverse();
        let Self { inv_z, scratch, .. } = self;
        let SpanScratch {
            vertices, snapped, ..
        } = scratch;
        for object in &scene.objects {
            let X_CO = Affine::from_pose(&(X_CW * object.X_WO));
            snap_vertices(&proj, &object.mesh, &X_CO, vertices, snapped);
            triangle_rows(&proj, &object.mesh, vertices, snapped, |run| {
                run.pixels(|p, z| {
                    if z > inv_z[p] {
                        inv_z[p] = z;
                    }
                });
            });
        }
        // A pixel a triangle drew has 1/z above the cleared 0 ([`Renderer::render`]'s
        // object index is set by the same test).
        depth_m.clear();
        depth_m.extend(
            inv_z
                .iter()
                .map(|&inv| if inv > 0.0 { 1.0 / inv } else { 0.0 }),
        );
        Ok(())
    }

    fn render_masks(
        &mut self,
        mesh: &RenderMesh,
        camera: &Camera,
        X_CO: &[Pose],
        masks: &mut MaskBatch,
    ) -> Result<()> {
        camera.validate()?;
        check_poses(X_CO)?;
        let proj = Projection::new(camera);
        masks.resize(camera.width, camera.height, X_CO.len());
        let n = (camera.width as usize * camera.height as usize).max(1);
        let draw = |scratch: &mut SpanScratch, (mask, X): (&mut [u8], &Pose)| {
            mask.fill(0);
            draw_mask(&proj, mesh, &Affine::from_pose(X), scratch, mask);
        };
        each_pose(&mut self.scratch, &mut masks.data, n, X_CO, draw);
        Ok(())
    }

    fn render_spans(
        &mut self,
        mesh: &RenderMesh,
        camera: &Camera,
        X_CO: &[Pose],
        spans: &mut SpanBatch,
    ) -> Result<()> {
        camera.validate()?;
        check_poses(X_CO)?;
        let proj = Projection::new(camera);
        spans.resize(camera.width, camera.height, X_CO.len());
        let rows = (camera.height as usize).max(1);
        let draw = |scratch: &mut SpanScratch, (rows, X): (&mut [[u32; 2]], &Pose)| {
            draw_spans(&proj, mesh, &Affine::from_pose(X), scratch, rows);
        };
        each_pose(&mut self.scratch, &mut spans.spans, rows, X_CO, draw);
        Ok(())
    }
}

/// Batches of fewer poses than this are drawn on the caller's thread
/// ([`Renderer::render_spans`], [`Renderer::render_masks`]).
const PARALLEL_MIN_POSES: usize = 64;

/// Calls `draw` with each pose of a batch and its `chunk` of `out`: on the caller's thread
/// with `scratch` for fewer than [`PARALLEL_MIN_POSES`] (a climb's steps: handing them to the
/// pool and waiting costs more than drawing them), else in parallel, each thread with
/// scratch of its own.
fn each_pose<T: Send>(
    scratch: &mut SpanScratch,
    out: &mut [T],
    chunk: usize,
    X_CO: &[Pose],
    draw: impl Fn(&mut SpanScratch, (&mut [T], &Pose)) + Sync + Send,
) {
    if X_CO.len() < PARALLEL_MIN_POSES {
        for job in out.chunks_mut(chunk).zip(X_CO) {
            draw(scratch, job);
        }
    } else {
        out.par_chunks_mut(chunk)
            .zip(X_CO.par_iter())
            .for_each_init(SpanScratch::default, draw);
    }
}

/// The scratch of [`draw_spans`], kept between renders.
#[derive(Debug, Clone, Default)]
pub(crate) struct SpanScratch {
    /// The mesh's vertices in the camera frame.
    vertices: Vec<[f32; 3]>,
    /// Each vertex snapped, `None` outside the view.
    snapped: Vec<Option<Snapped>>,
    /// A convex mesh's snapped vertices, then the left and right chains of the polygon
    /// around them ([`Projection::convex_rows`]).
    points: Vec<u64>,
    chains: [Vec<[i64; 2]>; 2],
}

/// Covers the pixels of `mesh` at `X_CO` in `spans` (one a row, [`SpanBatch::EMPTY`]
/// before): each row's first and last covered pixel, as [`draw_mask`] would cover them.
/// A mesh marked [`RenderMesh::convex`] with every vertex in view is drawn from the polygon
/// around its snapped vertices ([`Projection::convex_rows`]); any other, triangle by
/// triangle, each vertex inside the view snapped once (scratch), not once a triangle, and
/// triangles with a vertex outside clipped as [`Projection::triangle_rows`] clips them.
pub(crate) fn draw_spans(
    proj: &Projection,
    mesh: &RenderMesh,
    X_CO: &Affine,
    scratch: &mut SpanScratch,
    spans: &mut [[u32; 2]],
) {
    let SpanScratch {
        vertices,
        snapped,
        points,
        chains,
    } = scratch;
    let mut cover = |row: usize, first: usize, last: usize| {
        let span = &mut spans[row];
        span[0] = span[0].min(first as u32);
        span[1] = span[1].max(last as u32);
    };
    // A convex solid wholly in view: its outline is the polygon around its vertices.
    if mesh.convex && mesh.closed && proj.snap_points(mesh, X_CO, points) {
        proj.convex_rows(points, chains, &mut cover);
        return;
    }
    snap_vertices(proj, mesh, X_CO, vertices, snapped);
    triangle_rows(proj, mesh, vertices, snapped, |run| {
        cover(run.row, run.first, run.last);
    });
}

/// Snaps `mesh`'s vertices at `X_CO` once each: `vertices` gets them in the camera frame,
/// `snapped` each one snapped where it is finite and inside the view.
fn snap_vertices(
    proj: &Projection,
    mesh: &RenderMesh,
    X_CO: &Affine,
    vertices: &mut Vec<[f32; 3]>,
    snapped: &mut Vec<Option<Snapped>>,
) {
    vertices.clear();
    vertices.extend(mesh.positions.iter().map(|&p| X_CO.apply(p)));
    snapped.clear();
    snapped.extend(
        vertices
            .iter()
            .map(|&p| (p.iter().all(|v| v.is_finite()) && proj.inside(p)).then(|| proj.snap(p))),
    );
}

/// The covered rows of each triangle of `mesh` that both backends draw ([`front_faces`]),
/// from its vertices as [`snap_vertices`] left them: a triangle of snapped vertices is
/// rasterized as they are (the same pixels as [`Projection::triangle_rows`], which snaps
/// each triangle's own), one with a vertex outside the view is clipped.
fn triangle_rows(
    proj: &Projection,
    mesh: &RenderMesh,
    vertices: &[[f32; 3]],
    snapped: &[Option<Snapped>],
    mut row: impl FnMut(&RowSpan),
) {
    for tri in &mesh.triangles {
        let t = tri.map(|i| vertices.get(i as usize).copied().unwrap_or([f32::NAN; 3]));
        if facing(mesh, t).is_none() {
            continue;
        }
        match tri.map(|i| snapped.get(i as usize).copied().flatten()) {
            [Some(a), Some(b), Some(c)] => proj.raster_snapped([a, b, c], &mut row),
            _ => proj.triangle_rows(t, &mut row),
        }
    }
}

/// The triangles of `mesh` at `X_CO` as both backends draw them: camera-frame vertices
/// (transformed into `vertices`), triangles with a non-finite or missing vertex skipped, and
/// for closed meshes the faces not turned to the camera (counter-clockwise seen from
/// outside) culled. `face` gets the vertices, the unnormalised normal and the albedo.
#[inline]
pub(crate) fn front_faces(
    mesh: &RenderMesh,
    X_CO: &Affine,
    vertices: &mut Vec<[f32; 3]>,
    mut face: impl FnMut([[f32; 3]; 3], [f32; 3], [f32; 3]),
) {
    vertices.clear();
    vertices.extend(mesh.positions.iter().map(|&p| X_CO.apply(p)));
    for (tri, &albedo) in mesh.triangles.iter().zip(&mesh.colors) {
        let t = tri.map(|i| vertices.get(i as usize).copied().unwrap_or([f32::NAN; 3]));
        if let Some(n) = facing(mesh, t) {
            face(t, n, albedo);
        }
    }
}

/// The unnormalised normal of camera-frame triangle `t` of `mesh` where it is drawn: its
/// vertices finite and, for a closed mesh, turned to the camera.
#[inline]
fn facing(mesh: &RenderMesh, t: [[f32; 3]; 3]) -> Option<[f32; 3]> {
    if !t.iter().flatten().all(|v| v.is_finite()) {
        return None;
    }
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    (!(mesh.closed && dot(n, t[0]) >= 0.0)).then_some(n)
}

/// Covers the pixels of `mesh` at `X_CO` in `mask`, a row's run at a time.
pub(crate) fn draw_mask(
    proj: &Projection,
    mesh: &RenderMesh,
    X_CO: &Affine,
    scratch: &mut SpanScratch,
    mask: &mut [u8],
) {
    let SpanScratch {
        vertices, snapped, ..
    } = scratch;
    snap_vertices(proj, mesh, X_CO, vertices, snapped);
    triangle_rows(proj, mesh, vertices, snapped, |run| {
        mask[run.base + run.first..=run.base + run.last].fill(1);
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The library-free floor and round agree with `f32::floor` and `f32::round` everywhere:
    /// halves, negatives, integers, the edges of the exact range, huge values and NaN.
    #[test]
    fn floor_and_round_without_the_library_agree_with_it() {
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999997,
            -0.49999997,
            1.0,
            -1.0,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            16_777_217.0,
            1e12,
            -1e12,
            3e9,
            -3e9,
            f32::MAX,
            f32::MIN,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e-40,
        ];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        values.extend((0..100_000).map(|_| rng.random_range(-2e5f32..2e5)));
        values.extend((0..10_000).map(|k| (k as f32 - 5000.0) * 0.25));
        for v in values {
            assert_eq!(floor_to_int(v), v.floor() as i32, "floor {v}");
            assert_eq!(round_to_int(v), v.round() as i64, "round {v}");
        }
    }

    /// A jittered grid of triangles over the whole image (and beyond) covers every pixel
    /// centre exactly once: the top-left rule leaves no gap and no double cover on shared
    /// edges, whatever the vertex positions.
    #[test]
    fn shared_edges_cover_each_pixel_once() {
        let camera =
            Camera::look_at([0.0; 3], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0], 48, 40, 60.0).unwrap();
        let proj = Projection::new(&camera);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = 9;
        let mut grid = vec![[0.0f32; 3]; (n + 1) * (n + 1)];
        for j in 0..=n {
            for i in 0..=n {
                let interior = i > 0 && i < n && j > 0 && j < n;
                let jitter = |rng: &mut rand_chacha::ChaCha8Rng| {
                    if interior {
                        rng.random_range(-0.04..0.04)
                    } else {
                        0.0
                    }
                };
                let x = -1.0 + 2.0 * i as f32 / n as f32 + jitter(&mut rng);
                let y = -1.0 + 2.0 * j as f32 / n as f32 + jitter(&mut rng);
                // Some depth variation; all in front of the camera.
                grid[j * (n + 1) + i] = [x, y, 1.0 + 0.2 * rng.random::<f32>()];
            }
        }
        let mut hits = vec![0u32; 48 * 40];
        for j in 0..n {
            for i in 0..n {
                let v = |a: usize, b: usize| grid[b * (n + 1) + a];
                for t in [
                    [v(i, j), v(i + 1, j), v(i + 1, j + 1)],
                    [v(i, j), v(i + 1, j + 1), v(i, j + 1)],
                ] {
                    proj.triangle(t, &mut |p, _| hits[p] += 1);
                }
            }
        }
        assert!(hits.iter().all(|&h| h == 1), "{hits:?}");
    }

    #[test]
    fn a_packed_point_unpacks_and_sorts_by_row_then_column() {
        let values = [i32::MIN, -70_000, -1, 0, 1, 255, 256, 70_000, i32::MAX];
        let mut points = Vec::new();
        for &y in &values {
            for &x in &values {
                let key = pack_point(x, y);
                assert_eq!(unpack_point(key), [i64::from(x), i64::from(y)]);
                points.push((key, (y, x)));
            }
        }
        let by_key = {
            let mut p = points.clone();
            p.sort_by_key(|&(key, _)| key);
            p
        };
        points.sort_by_key(|&(_, yx)| yx);
        assert_eq!(by_key, points);
    }

    #[test]
    fn rounding_in_32_bits_is_rounding_in_64() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..100_000 {
            let v = (rng.random::<f32>() - 0.5) * 2.0f32.powi(rng.random_range(-2..31));
            assert_eq!(i64::from(round_to_i32(v)), round_to_int(v), "{v}");
        }
        for v in [
            0.5f32,
            -0.5,
            1.5,
            -1.5,
            0.49999997,
            -0.49999997,
            2.5e9,
            -2.5e9,
        ] {
            let want = round_to_int(v).clamp(i64::from(i32::MIN), i64::from(i32::MAX));
            assert_eq!(i64::from(round_to_i32(v)), want, "{v}");
        }
    }

    #[test]
    fn the_carried_floor_is_the_floor_division_of_every_row() {
        // Numerators and steps of either sign, divisors from 1 up: every row's quotient as
        // `div_euclid` gives it.
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut draw = |range: i64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % (2 * range as u64 + 1)) as i64 - range
        };
        for _ in 0..2000 {
            let (n, dn, d) = (draw(1 << 34), draw(1 << 20), draw(1 << 16).abs() + 1);
            let mut carried = RowFloor::new(n, dn, d);
            for row in 0..64 {
                assert_eq!(
                    carried.next(),
                    (n + row * dn).div_euclid(d),
                    "{n} {dn} {d} {row}"
                );
            }
        }
    }
}
