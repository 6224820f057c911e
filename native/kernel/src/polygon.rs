//! Planar polygons: the plane, ear clipping for small simple ones, and an edge BVH that makes
//! the crossing rule O(log n) per ray for the rest.
//!
//! A polygon of up to `MAX_EAR_CLIP` (1024) vertices that is simple becomes triangles
//! (`ear_clip`). Every other one (larger, or one ear clipping gives up on, as on most
//! self-intersecting ones) is kept whole: a ray meets its plane, and the hit point `(u, v)`,
//! in the projection that drops the normal's dominant axis, is inside by the even-odd
//! crossing rule. An edge from vertex `a` (vertex `i`) to `b`
//! (vertex `i - 1`, cyclically) crosses the ray from the point towards `+u` when
//!
//! ```text
//! (a.v > v) != (b.v > v)  &&  u < (b.u - a.u) * (v - a.v) / (b.v - a.v) + a.u
//! ```
//!
//! (half-open in `v`: horizontal edges never count and a vertex on the ray counts once), and the
//! point is inside when an odd number of edges cross. Testing every edge costs O(n) per ray,
//! about a millisecond for a million vertices.
//!
//! ## The edge BVH
//! `Polygons` keeps, for all kept polygons of a scene, three flat arrays:
//! - `edges`: each edge once, as its two projected endpoints in the orientation above (16 bytes),
//!   permuted so that every leaf's edges are contiguous;
//! - `nodes`: a binary BVH over the edges in depth-first order, each node holding the `v`-range
//!   `[vlo, vhi)` of its edges, `umax`, an upper bound of the `u` at which any of its edges can
//!   report a crossing, and `skip`, the node after its subtree; leaves also hold their edge range
//!   (24 bytes a node, leaves of 2 to `LEAF` (4) edges, so fewer than `n` nodes);
//! - `polys`: per polygon its plane and where its edges and nodes start.
//!
//! A query walks the nodes in order without a stack: a node is entered only if
//! `vlo <= v < vhi && u < umax`, otherwise the walk jumps to `skip`; a leaf's edges are tested
//! with the expression above, evaluated exactly as written. For every edge,
//! `(a.v > v) != (b.v > v)` holds exactly when `v` is in the edge's `[vlo, vhi)` (see
//! `Edge::v_range`), and the computed crossing is never above the edge's `umax` (see
//! `Edge::u_bound`, which allows for f32 rounding and gives up, with +inf, where the arithmetic
//! could overflow or underflow badly). So a skipped node holds no crossing edge, the same edges
//! are counted, and the answer is bit-for-bit that of testing every edge; the hit distance
//! comes from the same plane equation. (The tests check this against the edge-by-edge loop on
//! simple, self-intersecting and degenerate polygons, points on vertices and edges, and huge
//! and tiny coordinates.)
//!
//! The cost of a query is the nodes whose box the ray `[u, +inf) x {v}` passes: O(log n) plus
//! the parts of the outline the ray passes near (for a smooth outline, two or three nodes per
//! level, about 45 nodes and edges for a circle of a million vertices; a ray crossing a wavy
//! outline k times pays about k root-to-leaf paths). The build splits at the median of the
//! edge centres along the axis where they spread wider (`select_nth_unstable`), in place, and
//! takes each inner node's box from its children: O(n log n) time, no memory beyond the
//! result, recursion at most `ceil(log2 n)` deep. A million edges take 16 MB of edges and
//! 12.6 MB of nodes (2^19 - 1 of them).

use crate::ray::Ray;
use glam::Vec3A;

/// Largest polygon that is triangulated (ear clipping is quadratic); larger ones keep the
/// crossing test, accelerated by the edge BVH.
pub(crate) const MAX_EAR_CLIP: usize = 1024;

/// Most edges in one leaf of the edge BVH.
pub(crate) const LEAF: usize = 4;

#[inline]
pub(crate) fn comp(v: Vec3A, axis: u8) -> f32 {
    match axis {
        0 => v.x,
        1 => v.y,
        _ => v.z,
    }
}

/// The plane of a polygon and the projection it is tested in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Plane {
    /// Unit normal (Newell's method, so it follows the CCW winding of any simple polygon).
    pub normal: Vec3A,
    /// `normal . p` for the points of the plane (through the vertices' centroid).
    pub d: f32,
    /// The projection's axes: the two axes other than the normal's dominant one.
    pub axis_u: u8,
    /// See `axis_u`.
    pub axis_v: u8,
}

/// The projection's axes for a normal: the two other than its dominant axis.
#[inline]
fn axes(normal: Vec3A) -> (u8, u8) {
    let an = normal.abs();
    if an.x >= an.y && an.x >= an.z {
        (1, 2)
    } else if an.y >= an.z {
        (2, 0)
    } else {
        (0, 1)
    }
}

/// The plane of a polygon; `None` if it has fewer than 3 vertices or zero area.
pub(crate) fn plane(verts: &[Vec3A]) -> Option<Plane> {
    if verts.len() < 3 {
        return None;
    }
    let mut n = Vec3A::ZERO;
    for (i, a) in verts.iter().enumerate() {
        let b = verts[(i + 1) % verts.len()];
        n += Vec3A::new(
            (a.y - b.y) * (a.z + b.z),
            (a.z - b.z) * (a.x + b.x),
            (a.x - b.x) * (a.y + b.y),
        );
    }
    let normal = n.try_normalize()?;
    let (axis_u, axis_v) = axes(normal);
    let centroid = verts.iter().copied().sum::<Vec3A>() / verts.len() as f32;
    Some(Plane {
        normal,
        d: normal.dot(centroid),
        axis_u,
        axis_v,
    })
}

/// One edge in the projection: `a` is vertex `i`, `b` vertex `i - 1` (cyclically).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Edge {
    pub a: [f32; 2],
    pub b: [f32; 2],
}

impl Edge {
    /// The crossing rule for this edge and the point `(u, v)`.
    #[inline(always)]
    pub fn crosses(&self, u: f32, v: f32) -> bool {
        let (vi, vj) = (self.a, self.b);
        (vi[1] > v) != (vj[1] > v) && u < (vj[0] - vi[0]) * (v - vi[1]) / (vj[1] - vi[1]) + vi[0]
    }

    /// `[lo, hi)` such that `(a.v > v) != (b.v > v)` exactly when `lo <= v && v < hi`, for every
    /// f32 `v` (NaN included: neither holds). Empty (`lo = +inf, hi = -inf`) for horizontal edges.
    /// A NaN endpoint never compares greater, so the rule then reduces to `v` below the other one.
    pub fn v_range(&self) -> (f32, f32) {
        let (p, q) = (self.a[1], self.b[1]);
        const EMPTY: (f32, f32) = (f32::INFINITY, f32::NEG_INFINITY);
        match (p.is_nan(), q.is_nan()) {
            (true, true) => EMPTY,
            (true, false) => (f32::NEG_INFINITY, q),
            (false, true) => (f32::NEG_INFINITY, p),
            _ if p == q => EMPTY,
            _ => (p.min(q), p.max(q)),
        }
    }

    /// An upper bound on the crossing `(b.u - a.u) * (v - a.v) / (b.v - a.v) + a.u` as f32
    /// computes it, over every `v` in [`Edge::v_range`] (-inf if that is empty, +inf if no
    /// bound is given).
    ///
    /// For such a `v`, `v - a.v` lies between 0 and `b.v - a.v`, and rounding is monotonic, so
    /// the computed differences keep that order and their real ratio `r` is in `[0, 1]`: the
    /// crossing is `a.u + (b.u - a.u) r`, at most `max(a.u, b.u)`, up to the roundings of the
    /// difference, product, quotient and sum. Provided nothing overflows
    /// (`|a.u| + |b.u|`, `|a.v| + |b.v|` and their product below 2^120) and
    /// `|b.v - a.v| >= 2^-100` (an underflow of the product, at most 2^-150, then grows to at
    /// most 2^-50 by the division), the standard error model (relative error at most 2^-24 a
    /// rounding) gives `x <= max(a.u, b.u) + 4.01 * 2^-24 * (|a.u| + |b.u|) + 2^-48`. The bound
    /// returned is `max(a.u, b.u) + 2^-20 * (|a.u| + |b.u|) + 2^-40`, summed in f64 and rounded
    /// up to f32; otherwise (huge or tiny coordinates, non-finite ones) +inf.
    pub fn u_bound(&self) -> f32 {
        let (lo, hi) = self.v_range();
        // (never NaN)
        if lo >= hi {
            return f32::NEG_INFINITY;
        }
        let (a, b) = (self.a, self.b);
        let su = a[0].abs() as f64 + b[0].abs() as f64;
        let sv = a[1].abs() as f64 + b[1].abs() as f64;
        let dv = (b[1] as f64 - a[1] as f64).abs();
        let big = 2f64.powi(120);
        if !(su < big && sv < big && su * sv < big && dv >= 2f64.powi(-100)) {
            return f32::INFINITY;
        }
        let m = a[0].max(b[0]) as f64 + su * 2f64.powi(-20) + 2f64.powi(-40);
        let f = m as f32;
        if (f as f64) < m {
            f.next_up()
        } else {
            f
        }
    }
}

/// A node of the edge BVH (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Node {
    pub vlo: f32,
    pub vhi: f32,
    pub umax: f32,
    /// Index (within the polygon's nodes) of the first node after this subtree.
    pub skip: u32,
    /// Leaf: first edge (within the polygon's edges); inner node: unused.
    pub first: u32,
    /// Leaf: edge count (at least 1); inner node: 0, the children follow it.
    pub count: u32,
}

/// A kept polygon: its plane and its slices of [`Polygons`]' edges and nodes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PolygonData {
    pub plane: Plane,
    pub first_edge: u32,
    pub edge_count: u32,
    pub first_node: u32,
    pub node_count: u32,
}

/// What a query visited: nodes whose box was tested and edges whose crossing was tested.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Visits {
    pub nodes: u32,
    pub edges: u32,
}

/// All kept (not triangulated) polygons of a scene, with their edge BVHs.
#[derive(Clone, Debug, Default)]
pub(crate) struct Polygons {
    polys: Vec<PolygonData>,
    edges: Vec<Edge>,
    nodes: Vec<Node>,
}

impl Polygons {
    /// Keeps a polygon whose `plane` is [`plane`]`(verts)`, building its edge BVH; returns its
    /// index, or `None` (the polygon is dropped) if the index space of the arrays is exhausted,
    /// which the limits on file size make unreachable.
    pub fn add(&mut self, verts: &[Vec3A], plane: Plane) -> Option<u32> {
        let n = verts.len();
        let k = u32::try_from(self.polys.len()).ok()?;
        let first_edge = u32::try_from(self.edges.len()).ok()?;
        let first_node = u32::try_from(self.nodes.len()).ok()?;
        u32::try_from(self.edges.len() + n).ok()?;
        u32::try_from(self.nodes.len() + 2 * n).ok()?;
        let proj = |p: Vec3A| [comp(p, plane.axis_u), comp(p, plane.axis_v)];
        self.edges.reserve(n);
        let mut prev = proj(*verts.last()?);
        for p in verts {
            let a = proj(*p);
            self.edges.push(Edge { a, b: prev });
            prev = a;
        }
        let edges = self.edges.get_mut(first_edge as usize..)?;
        build(edges, 0, first_node as usize, &mut self.nodes);
        let node_count = u32::try_from(self.nodes.len()).ok()? - first_node;
        self.polys.push(PolygonData {
            plane,
            first_edge,
            edge_count: n as u32,
            first_node,
            node_count,
        });
        Some(k)
    }

    /// Gives back the spare capacity of the arrays (once the scene is complete).
    pub fn shrink_to_fit(&mut self) {
        self.polys.shrink_to_fit();
        self.edges.shrink_to_fit();
        self.nodes.shrink_to_fit();
    }

    /// The polygon's unit normal.
    pub fn normal(&self, k: u32) -> Option<Vec3A> {
        self.polys.get(k as usize).map(|p| p.plane.normal)
    }

    /// The polygon's data.
    #[cfg(test)]
    pub fn get(&self, k: u32) -> Option<&PolygonData> {
        self.polys.get(k as usize)
    }

    /// Nearest hit of polygon `k` in `(tmin, tmax)`.
    #[inline]
    pub fn hit(&self, k: u32, ray: &Ray, tmin: f32, tmax: f32) -> Option<f32> {
        let p = self.polys.get(k as usize)?;
        let (normal, d) = (p.plane.normal, p.plane.d);
        let dn = normal.dot(ray.dir);
        if dn == 0.0 {
            return None;
        }
        let t = (d - normal.dot(ray.origin)) / dn;
        if !(t > tmin && t < tmax) {
            return None;
        }
        let hit = ray.at(t);
        let u = comp(hit, p.plane.axis_u);
        let v = comp(hit, p.plane.axis_v);
        if self.contains(p, u, v, &mut Visits::default()) {
            Some(t)
        } else {
            None
        }
    }

    /// The crossing rule for the projected point `(u, v)`, walking the polygon's edge BVH;
    /// counts what it visits.
    #[inline]
    pub fn contains(&self, p: &PolygonData, u: f32, v: f32, visits: &mut Visits) -> bool {
        let nodes = p.first_node as usize..p.first_node as usize + p.node_count as usize;
        let edges = p.first_edge as usize..p.first_edge as usize + p.edge_count as usize;
        let (Some(nodes), Some(edges)) = (self.nodes.get(nodes), self.edges.get(edges)) else {
            return false;
        };
        let mut inside = false;
        let mut i = 0usize;
        while let Some(n) = nodes.get(i) {
            visits.nodes += 1;
            if n.vlo <= v && v < n.vhi && u < n.umax {
                if n.count == 0 {
                    i += 1;
                    continue;
                }
                let leaf = n.first as usize..n.first as usize + n.count as usize;
                for e in edges.get(leaf).unwrap_or(&[]) {
                    visits.edges += 1;
                    inside ^= e.crosses(u, v);
                }
            }
            // `skip` is always past `i`; the max only guards termination
            i = (n.skip as usize).max(i + 1);
        }
        inside
    }

    /// The polygon's edges in BVH order (each once, in its crossing-rule orientation).
    #[cfg(test)]
    pub fn edges(&self, p: &PolygonData) -> &[Edge] {
        let r = p.first_edge as usize..p.first_edge as usize + p.edge_count as usize;
        self.edges.get(r).unwrap_or(&[])
    }

    /// The polygon's BVH nodes.
    #[cfg(test)]
    pub fn nodes(&self, p: &PolygonData) -> &[Node] {
        let r = p.first_node as usize..p.first_node as usize + p.node_count as usize;
        self.nodes.get(r).unwrap_or(&[])
    }
}

/// Centre of the edge's extent along `axis` (halves summed, so it cannot overflow).
#[inline]
fn centre(e: &Edge, axis: usize) -> f32 {
    e.a[axis] * 0.5 + e.b[axis] * 0.5
}

/// Appends the subtree over `edges` (edges `offset..` of the polygon) to `nodes`, whose
/// polygon's nodes start at `base`, in depth-first order; reorders `edges` into leaf order.
/// Returns the subtree's `(vlo, vhi, umax)`, which inner nodes take from their children.
fn build(edges: &mut [Edge], offset: usize, base: usize, nodes: &mut Vec<Node>) -> [f32; 3] {
    let me = nodes.len();
    nodes.push(Node {
        vlo: f32::INFINITY,
        vhi: f32::NEG_INFINITY,
        umax: f32::NEG_INFINITY,
        skip: 0,
        first: offset as u32,
        count: 0,
    });
    let bounds = if edges.len() <= LEAF {
        if let Some(n) = nodes.get_mut(me) {
            n.count = edges.len() as u32;
        }
        edges.iter().fold(
            [f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY],
            |b, e| {
                let (lo, hi) = e.v_range();
                [b[0].min(lo), b[1].max(hi), b[2].max(e.u_bound())]
            },
        )
    } else {
        // split at the median centre along the axis where the centres spread wider
        let mut cmin = [f32::INFINITY; 2];
        let mut cmax = [f32::NEG_INFINITY; 2];
        for e in edges.iter() {
            for a in 0..2 {
                let c = centre(e, a);
                cmin[a] = cmin[a].min(c);
                cmax[a] = cmax[a].max(c);
            }
        }
        let ext = |a: usize| cmax[a] * 0.5 - cmin[a] * 0.5;
        let axis = usize::from(ext(1) >= ext(0));
        let mid = edges.len() / 2;
        edges.select_nth_unstable_by(mid, |x, y| centre(x, axis).total_cmp(&centre(y, axis)));
        let (left, right) = edges.split_at_mut(mid);
        let l = build(left, offset, base, nodes);
        let r = build(right, offset + mid, base, nodes);
        [l[0].min(r[0]), l[1].max(r[1]), l[2].max(r[2])]
    };
    let skip = (nodes.len() - base) as u32;
    if let Some(n) = nodes.get_mut(me) {
        [n.vlo, n.vhi, n.umax] = bounds;
        n.skip = skip;
    }
    bounds
}

/// Triangulates a simple planar polygon (convex or concave) by ear clipping in the projection
/// that drops the normal's dominant axis. Returns vertex-index triples in the polygon's own
/// winding, or `None` if the polygon is not simple (then the caller keeps the crossing test).
/// Zero-area ears (collinear vertices) are clipped without emitting a triangle.
pub(crate) fn ear_clip(verts: &[Vec3A], normal: Vec3A) -> Option<Vec<[usize; 3]>> {
    let n = verts.len();
    if !(3..=MAX_EAR_CLIP).contains(&n) {
        return None;
    }
    let (u, v) = axes(normal);
    let p: Vec<[f32; 2]> = verts.iter().map(|q| [comp(*q, u), comp(*q, v)]).collect();
    // orientation of the projection
    let mut area = 0.0f32;
    for i in 0..n {
        let a = p[i];
        let b = p[(i + 1) % n];
        area += a[0] * b[1] - b[0] * a[1];
    }
    if area == 0.0 {
        return None;
    }
    let sign = area.signum();
    let cross = |a: [f32; 2], b: [f32; 2], c: [f32; 2]| -> f32 {
        ((b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])) * sign
    };
    let inside = |q: [f32; 2], a: [f32; 2], b: [f32; 2], c: [f32; 2]| -> bool {
        let d1 = ((b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0])) * sign;
        let d2 = ((c[0] - b[0]) * (q[1] - b[1]) - (c[1] - b[1]) * (q[0] - b[0])) * sign;
        let d3 = ((a[0] - c[0]) * (q[1] - c[1]) - (a[1] - c[1]) * (q[0] - c[0])) * sign;
        d1 >= 0.0 && d2 >= 0.0 && d3 >= 0.0
    };
    let mut idx: Vec<usize> = (0..n).collect();
    let mut out = Vec::with_capacity(n - 2);
    let mut i = 0;
    let mut since_clip = 0;
    while idx.len() > 3 {
        let m = idx.len();
        let (ia, ib, ic) = (idx[(i + m - 1) % m], idx[i % m], idx[(i + 1) % m]);
        let (a, b, c) = (p[ia], p[ib], p[ic]);
        let cr = cross(a, b, c);
        let is_ear = if cr == 0.0 {
            true
        } else if cr > 0.0 {
            !idx.iter().any(|&k| {
                k != ia
                    && k != ib
                    && k != ic
                    && p[k] != a
                    && p[k] != b
                    && p[k] != c
                    && inside(p[k], a, b, c)
            })
        } else {
            false
        };
        if is_ear {
            if cr != 0.0 {
                out.push([ia, ib, ic]);
            }
            idx.remove(i % m);
            since_clip = 0;
            if i >= idx.len() {
                i = 0;
            }
        } else {
            i = (i + 1) % m;
            since_clip += 1;
            if since_clip > m {
                return None;
            }
        }
    }
    if let [a, b, c] = idx[..] {
        if cross(p[a], p[b], p[c]) != 0.0 {
            out.push([a, b, c]);
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The crossing test as it was before the edge BVH (every edge, in vertex order), over the
    /// projected vertices: the reference the BVH must equal bit for bit.
    fn linear_hit(p: &Plane, vs: &[[f32; 2]], ray: &Ray, tmin: f32, tmax: f32) -> Option<f32> {
        let dn = p.normal.dot(ray.dir);
        if dn == 0.0 {
            return None;
        }
        let t = (p.d - p.normal.dot(ray.origin)) / dn;
        if !(t > tmin && t < tmax) {
            return None;
        }
        let hit = ray.at(t);
        let tx = comp(hit, p.axis_u);
        let ty = comp(hit, p.axis_v);
        linear_inside(vs, tx, ty).then_some(t)
    }

    fn linear_inside(vs: &[[f32; 2]], tx: f32, ty: f32) -> bool {
        let mut inside = false;
        let mut j = vs.len() - 1;
        for (i, vi) in vs.iter().enumerate() {
            let vj = vs[j];
            if (vi[1] > ty) != (vj[1] > ty)
                && tx < (vj[0] - vi[0]) * (ty - vi[1]) / (vj[1] - vi[1]) + vi[0]
            {
                inside = !inside;
            }
            j = i;
        }
        inside
    }

    /// splitmix64
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }
        /// Uniform in [0, 1).
        fn unit(&mut self) -> f32 {
            (self.next() >> 40) as f32 / (1u64 << 24) as f32
        }
        fn range(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * self.unit()
        }
        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }
    }

    /// Polygons in the plane z = 0 (2D shapes), of many kinds.
    fn shape(rng: &mut Rng, kind: usize, n: usize) -> Vec<[f32; 2]> {
        let tau = std::f32::consts::TAU;
        match kind {
            // simple, star-shaped: random radii at increasing angles
            0 => (0..n)
                .map(|i| {
                    let a = i as f32 / n as f32 * tau;
                    let r = rng.range(0.2, 1.0);
                    [r * a.cos(), r * a.sin()]
                })
                .collect(),
            // self-intersecting: uniform random points
            1 => (0..n)
                .map(|_| [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)])
                .collect(),
            // on a coarse grid: many equal v (horizontal edges, vertices on query lines),
            // repeated and collinear vertices
            2 => (0..n)
                .map(|_| [rng.below(9) as f32 * 0.25, rng.below(9) as f32 * 0.25])
                .collect(),
            // a random walk (long chains of short edges crossing themselves)
            3 => {
                let mut p = [0.0f32, 0.0];
                (0..n)
                    .map(|_| {
                        p = [p[0] + rng.range(-0.1, 0.1), p[1] + rng.range(-0.1, 0.1)];
                        p
                    })
                    .collect()
            }
            // a circle wound three times (every point inside is crossed 6 times or 0)
            4 => (0..n)
                .map(|i| {
                    let a = 3.0 * i as f32 / n as f32 * tau;
                    [a.cos(), a.sin()]
                })
                .collect(),
            // a comb: teeth along u, so a ray crosses many of them
            _ => {
                let teeth = (n / 4).max(1);
                let mut v: Vec<[f32; 2]> = Vec::with_capacity(4 * teeth + 2);
                for t in 0..teeth {
                    let x = t as f32 / teeth as f32;
                    let w = 0.5 / teeth as f32;
                    v.extend([[x, 0.0], [x, 1.0], [x + w, 1.0], [x + w, 0.1]]);
                }
                v.extend([[1.0, 0.1], [1.0, -0.1]]);
                v
            }
        }
    }

    /// Adds a 2D shape as a polygon of the plane z = 0, returning its data and the projected
    /// vertices (which, for z = 0, are the shape itself).
    fn keep(
        ps: &mut Polygons,
        vs2: &[[f32; 2]],
        scale: f32,
    ) -> Option<(PolygonData, Vec<[f32; 2]>)> {
        let vs: Vec<Vec3A> = vs2
            .iter()
            .map(|p| Vec3A::new(p[0] * scale, p[1] * scale, 0.0))
            .collect();
        // shapes of zero area (or whose area under- or overflows) are tested in z = 0 anyway
        let plane = plane(&vs).unwrap_or(Plane {
            normal: Vec3A::Z,
            d: 0.0,
            axis_u: 0,
            axis_v: 1,
        });
        let k = ps.add(&vs, plane)?;
        let proj = vs
            .iter()
            .map(|p| [comp(*p, plane.axis_u), comp(*p, plane.axis_v)])
            .collect();
        Some((*ps.get(k)?, proj))
    }

    /// Query points that stress the half-open rule: vertices, their neighbours in f32,
    /// points exactly on an edge's computed crossing and one f32 step either side, random ones.
    fn queries(rng: &mut Rng, vs: &[[f32; 2]], count: usize) -> Vec<[f32; 2]> {
        let n = vs.len();
        let mut out = Vec::with_capacity(count);
        while out.len() < count {
            let i = rng.below(n);
            let (a, b) = (vs[i], vs[(i + n - 1) % n]);
            match rng.below(6) {
                0 => out.push(a),
                1 => out.push([a[0].next_down(), a[1].next_up()]),
                2 => {
                    // on the edge at a random v, at the crossing the rule computes
                    let v = a[1] + (b[1] - a[1]) * rng.unit();
                    if (a[1] > v) != (b[1] > v) {
                        let x = (b[0] - a[0]) * (v - a[1]) / (b[1] - a[1]) + a[0];
                        out.extend([[x, v], [x.next_down(), v], [x.next_up(), v]]);
                    }
                }
                3 => out.push([rng.range(-1.5, 1.5), a[1]]),
                4 => {
                    let (x0, x1) = (a[0].min(b[0]), a[0].max(b[0]));
                    out.push([rng.range(x0, x1), rng.range(a[1].min(b[1]), a[1].max(b[1]))]);
                    out.push([x1, rng.range(-1.5, 1.5)]);
                }
                _ => out.push([rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)]),
            }
        }
        out
    }

    #[test]
    fn edge_bvh_equals_the_crossing_rule_in_2d() {
        let mut rng = Rng(7);
        let mut checked = 0usize;
        let mut inside = 0usize;
        for &n in &[3usize, 4, 5, 7, 9, 16, 33, 100, 1000, 5000] {
            for kind in 0..6 {
                for &scale in &[1.0f32, 1e-30, 3e30, 1e37] {
                    let mut ps = Polygons::default();
                    let vs = shape(&mut rng, kind, n);
                    let Some((p, proj)) = keep(&mut ps, &vs, scale) else {
                        continue;
                    };
                    let qs = queries(&mut rng, &proj, 400);
                    for q in qs {
                        let want = linear_inside(&proj, q[0], q[1]);
                        let got = ps.contains(&p, q[0], q[1], &mut Visits::default());
                        assert_eq!(got, want, "kind {kind}, n {n}, scale {scale}, point {q:?}");
                        checked += 1;
                        inside += usize::from(want);
                    }
                }
            }
        }
        // the queries are not all on one side
        assert!(
            inside > checked / 10 && inside < checked * 9 / 10,
            "{inside} of {checked}"
        );
    }

    #[test]
    fn edge_bvh_equals_the_crossing_rule_for_rays() {
        let mut rng = Rng(11);
        for &n in &[5usize, 8, 64, 1025, 3000] {
            for kind in 0..6 {
                // embed the shape in a tilted plane, so the projection is not the shape's own
                let vs2 = shape(&mut rng, kind, n);
                let (su, cu) = rng.range(0.0, std::f32::consts::TAU).sin_cos();
                let tilt = rng.range(-1.2, 1.2);
                let e1 = Vec3A::new(cu, su, 0.0);
                let e2 = Vec3A::new(-su * tilt.cos(), cu * tilt.cos(), tilt.sin());
                let origin = Vec3A::new(0.3, -0.2, 0.1);
                let vs: Vec<Vec3A> = vs2.iter().map(|p| origin + e1 * p[0] + e2 * p[1]).collect();
                let Some(pl) = plane(&vs) else {
                    continue;
                };
                let mut ps = Polygons::default();
                let k = ps.add(&vs, pl).unwrap();
                let proj: Vec<[f32; 2]> = vs
                    .iter()
                    .map(|p| [comp(*p, pl.axis_u), comp(*p, pl.axis_v)])
                    .collect();
                for _ in 0..2000 {
                    // aim at a vertex, nudged by a tiny amount or not at all, or anywhere
                    let target = match rng.below(3) {
                        0 => vs[rng.below(n)],
                        1 => {
                            let i = rng.below(n);
                            vs[i].lerp(vs[(i + 1) % n], rng.unit())
                        }
                        _ => origin + e1 * rng.range(-1.5, 1.5) + e2 * rng.range(-1.5, 1.5),
                    };
                    let from = Vec3A::new(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), 4.0)
                        * if rng.below(2) == 0 { 1.0 } else { -1.0 };
                    let ray = Ray::new(from, (target - from).normalize());
                    let want = linear_hit(&pl, &proj, &ray, 0.0, f32::INFINITY);
                    let got = ps.hit(k, &ray, 0.0, f32::INFINITY);
                    assert_eq!(
                        got.map(f32::to_bits),
                        want.map(f32::to_bits),
                        "kind {kind}, n {n}, ray {ray:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn extreme_coordinates_and_nan_points() {
        // huge coordinates (no u bound), tiny edges, a NaN query point
        let vs2 = [
            [-3e38f32, -3e38],
            [3e38, -3e38],
            [0.0, 3e38],
            [1e-38, 1e-38],
            [2e-38, 3e-38],
            [1.0, 1e-39],
        ];
        let mut ps = Polygons::default();
        let vs: Vec<Vec3A> = vs2.iter().map(|p| Vec3A::new(p[0], p[1], 0.0)).collect();
        let pl = Plane {
            normal: Vec3A::Z,
            d: 0.0,
            axis_u: 0,
            axis_v: 1,
        };
        let k = ps.add(&vs, pl).unwrap();
        let p = *ps.get(k).unwrap();
        let mut rng = Rng(3);
        let mut pts = queries(&mut rng, &vs2, 2000);
        pts.extend([
            [f32::NAN, 0.0],
            [0.0, f32::NAN],
            [0.0, 0.0],
            [f32::INFINITY, 0.0],
        ]);
        pts.extend([[f32::NEG_INFINITY, 1.0], [0.0, f32::NEG_INFINITY]]);
        for q in pts {
            assert_eq!(
                ps.contains(&p, q[0], q[1], &mut Visits::default()),
                linear_inside(&vs2, q[0], q[1]),
                "{q:?}"
            );
        }
    }

    #[test]
    fn u_bound_bounds_the_computed_crossing() {
        let mut rng = Rng(5);
        // coordinates of mixed magnitudes, 1e-30 to 1e29
        let c = |rng: &mut Rng| rng.range(-1.0, 1.0) * 10f32.powi(rng.below(60) as i32 - 30);
        for _ in 0..200_000 {
            let e = Edge {
                a: [c(&mut rng), c(&mut rng)],
                b: [c(&mut rng), c(&mut rng)],
            };
            let (lo, hi) = e.v_range();
            if lo >= hi {
                continue;
            }
            let bound = e.u_bound();
            for v in [lo, hi.next_down(), lo + (hi - lo) * rng.unit()] {
                if lo <= v && v < hi {
                    let (a, b) = (e.a, e.b);
                    let x = (b[0] - a[0]) * (v - a[1]) / (b[1] - a[1]) + a[0];
                    assert!(x <= bound, "{e:?} v {v}: {x} > {bound}");
                }
            }
        }
    }

    #[test]
    fn tree_covers_every_edge_once_and_skips_forward() {
        let mut rng = Rng(9);
        let vs = shape(&mut rng, 1, 777);
        let mut ps = Polygons::default();
        let (p, proj) = keep(&mut ps, &vs, 1.0).unwrap();
        let nodes = ps.nodes(&p);
        assert!(nodes.len() < proj.len());
        let mut covered = vec![0u32; proj.len()];
        for (i, n) in nodes.iter().enumerate() {
            assert!(n.skip as usize > i && n.skip as usize <= nodes.len());
            if n.count > 0 {
                assert!((1..=LEAF as u32).contains(&n.count));
                for c in &mut covered[n.first as usize..(n.first + n.count) as usize] {
                    *c += 1;
                }
            }
        }
        assert!(covered.iter().all(|&c| c == 1));
        // the edges are the polygon's own, each once
        let mut want: Vec<_> = (0..proj.len())
            .map(|i| (proj[i], proj[(i + proj.len() - 1) % proj.len()]))
            .map(|(a, b)| [a[0], a[1], b[0], b[1]].map(f32::to_bits))
            .collect();
        let mut got: Vec<_> = ps
            .edges(&p)
            .iter()
            .map(|e| [e.a[0], e.a[1], e.b[0], e.b[1]].map(f32::to_bits))
            .collect();
        want.sort_unstable();
        got.sort_unstable();
        assert_eq!(got, want);
    }

    /// `n` vertices on a circle of radius 1, or on a concave flower (9 petals, 150 ripples: the
    /// outline of `examples/polygon.rs`).
    fn round(n: usize, flower: bool) -> Vec<[f32; 2]> {
        (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                let r = if flower {
                    0.75 + 0.2 * (9.0 * a).cos() + 0.03 * (150.0 * a).cos()
                } else {
                    1.0
                };
                [(r * a.cos()) as f32, (r * a.sin()) as f32]
            })
            .collect()
    }

    /// Per-query cost (nodes plus edges visited) for 6000 points: half near the outline (see
    /// `queries`), half uniform over the box around it. Every `sample`-th point is also tested
    /// edge by edge (about a millisecond for a million edges); returns the worst cost, the
    /// mean cost, and the sampled points' crossing counts and costs.
    fn costs(vs: &[[f32; 2]], sample: usize) -> (u32, f64, Vec<(usize, u32)>) {
        let mut ps = Polygons::default();
        let (p, proj) = keep(&mut ps, vs, 1.0).unwrap();
        assert!(ps.nodes(&p).len() < vs.len());
        let mut rng = Rng(1);
        let mut pts = queries(&mut rng, &proj, 3000);
        pts.extend((0..3000).map(|_| [rng.range(-1.2, 1.2), rng.range(-1.2, 1.2)]));
        let (mut worst, mut total, mut sampled) = (0u32, 0u64, Vec::new());
        for (i, q) in pts.iter().enumerate() {
            let mut visits = Visits::default();
            let inside = ps.contains(&p, q[0], q[1], &mut visits);
            let cost = visits.nodes + visits.edges;
            if i % sample == 0 {
                let n = proj.len();
                let crossings = (0..n)
                    .filter(|&i| {
                        let e = Edge {
                            a: proj[i],
                            b: proj[(i + n - 1) % n],
                        };
                        e.crosses(q[0], q[1])
                    })
                    .count();
                assert_eq!(inside, crossings % 2 == 1, "{q:?}");
                assert_eq!(inside, linear_inside(&proj, q[0], q[1]), "{q:?}");
                sampled.push((crossings, cost));
            }
            worst = worst.max(cost);
            total += cost as u64;
        }
        (worst, total as f64 / pts.len() as f64, sampled)
    }

    /// The cost of a query grows with log n, not n: a point tested against a circle of
    /// 2^20 vertices visits fewer than 200 nodes and edges (in total, not per level), inside,
    /// outside or next to the outline, and on average less than twice what it visits for
    /// 2^14 vertices (64 times fewer). On the flower, whose outline a ray may pass many
    /// times, a point costs at most 10 log2 n (200) per crossing of its ray, plus 200.
    #[test]
    fn million_vertex_queries_visit_few_nodes() {
        let (worst, mean, _) = costs(&round(1 << 20, false), 100);
        let (_, mean_small, _) = costs(&round(1 << 14, false), 100);
        println!("circle: worst {worst}, mean {mean:.1} (2^14 vertices: {mean_small:.1})");
        assert!(worst < 200, "worst {worst}");
        assert!(mean < 2.0 * mean_small, "{mean} vs {mean_small}");
        let (worst, mean, sampled) = costs(&round(1 << 20, true), 20);
        println!("flower: worst {worst}, mean {mean:.1}");
        for (crossings, cost) in sampled {
            assert!(
                cost as usize <= 200 * (1 + crossings),
                "{cost} for {crossings} crossings"
            );
        }
    }
}

#[cfg(test)]
mod ear_tests {
    use super::*;

    fn area(vs: &[Vec3A], tris: &[[usize; 3]]) -> f32 {
        tris.iter()
            .map(|t| (vs[t[1]] - vs[t[0]]).cross(vs[t[2]] - vs[t[0]]).z * 0.5)
            .sum()
    }

    #[test]
    fn concave_polygon_triangulates_exactly() {
        // "L" shape of area 3, CCW
        let vs: Vec<Vec3A> = [[0., 0.], [2., 0.], [2., 1.], [1., 1.], [1., 2.], [0., 2.]]
            .iter()
            .map(|a| Vec3A::new(a[0], a[1], 0.0))
            .collect();
        let t = ear_clip(&vs, Vec3A::Z).unwrap();
        assert_eq!(t.len(), 4);
        assert!((area(&vs, &t) - 3.0).abs() < 1e-6);
        // every triangle keeps the winding (positive z area)
        assert!(t
            .iter()
            .all(|t| (vs[t[1]] - vs[t[0]]).cross(vs[t[2]] - vs[t[0]]).z > 0.0));
        // a gear-like star: 2k points alternating radius
        let k = 72;
        let star: Vec<Vec3A> = (0..2 * k)
            .map(|i| {
                let a = i as f32 / (2 * k) as f32 * std::f32::consts::TAU;
                let r = if i % 2 == 0 { 1.0 } else { 0.8 };
                Vec3A::new(r * a.cos(), r * a.sin(), 0.5)
            })
            .collect();
        let t = ear_clip(&star, Vec3A::Z).unwrap();
        assert_eq!(t.len(), 2 * k - 2);
        let mut want = 0.0;
        for i in 0..star.len() {
            let a = star[i];
            let b = star[(i + 1) % star.len()];
            want += (a.x * b.y - b.x * a.y) * 0.5;
        }
        assert!((area(&star, &t) - want).abs() < 1e-4);
        // clockwise input keeps its (clockwise) winding
        let rev: Vec<Vec3A> = vs.iter().rev().copied().collect();
        let t = ear_clip(&rev, -Vec3A::Z).unwrap();
        assert!((area(&rev, &t) + 3.0).abs() < 1e-6);
    }
}
