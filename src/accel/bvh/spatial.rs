//! Spatial splits (Stich, Friedrich and Dietrich 2009, "Spatial Splits in
//! Bounding Volume Hierarchies"; Embree's `HeuristicSpatialSplit`): a node
//! may be divided by a plane instead of by its references' centroids, and
//! a triangle the plane crosses is then referenced on both sides, each
//! reference bounded by the part of the triangle on its side. Where large
//! triangles cross many small ones (a floor under a building, a wall behind
//! a bunny), an object split leaves two heavily overlapping children; a
//! spatial split does not.
//!
//! The search bins the node's box (not its centroids) into `BINS` slabs
//! per axis; each reference adds the box of its triangle clipped to every
//! slab it spans, and counts once where it enters and once where it exits.
//! Only sets whose best object split leaves children overlapping by more
//! than `ALPHA` of the root's area are searched (the paper's criterion), and
//! only while the build's reference budget lasts (`BuildSet`'s spare room).
//!
//! **Decided per scene** (`wide::split_choice`; `PATHTRACER_NATIVE_SPLITS=B`
//! fixes B extra references per primitive), because on most scenes it did
//! not pay. Measured (2-vCPU AMD EPYC, 1 thread, best of 5 passes, two alternating
//! runs, budget 0.3, Mrays/s without -> with): random rays on beetle
//! 11.6-11.8 -> 12.1-12.2 and the subdivided bunny 7.5-7.6 -> 7.9-8.2, but
//! stadium:500k 10.5 -> 9.7 (its SAH cost rose, 8.97 -> 9.61: the greedy
//! top-down choice chops the bowl's large triangles into pieces that spread
//! through the tree), grass:300k 1.85-1.97 -> 1.67-1.73, CBbunny's shadow
//! rays 37.4-37.7 -> 33.1-34.0 and arch:500k's 91-93 -> 47 (the floor
//! slabs that occlude most shadow rays leave the root's leaf, as with
//! pre-splitting); builds 4-9x slower (the subdivided bunny's 1.2 s against
//! Embree's 0.34 s), the clipping of every slab a reference spans being
//! most of it. Embree's own spatial-split builder (`embree-high` in the
//! bench) moves the same way on CBbunny, stadium and arch.
//!
//! Conservative: the clipped boxes are those of the exact clipped polygon,
//! widened by `2^-20` of the coordinates on the axes other than the
//! split's (where intersection points are rounded) and intersected with the
//! reference's previous box; on the split axis the plane position is used
//! exactly, on both sides. So each piece of a triangle lies inside the box
//! of some reference to it, and a ray that hits the triangle enters that box.

use super::{blocks, Box4, PrimRef, TRAVERSAL_COST};
use crate::accel::prims::PrimTable;
use glam::{Vec3, Vec4};
use rayon::prelude::*;

/// Slabs per axis of the spatial search (as Embree's spatial binner), at
/// most: sets of fewer references get fewer (`bins_for`), since a set's
/// small references span more of its slabs, and each slab spanned costs a
/// clip.
const BINS: usize = 16;

fn bins_for(n: usize) -> usize {
    match n {
        0..80 => 4,
        80..240 => 8,
        _ => BINS,
    }
}

/// A set is searched for spatial splits only when its best object split's
/// children overlap by more than this fraction of the root's half area
/// (Stich et al.'s alpha).
pub(super) const ALPHA: f32 = 1e-5;

/// Sets with more references than this are binned in parallel.
const PARALLEL: usize = 1 << 15;
const CHUNK: usize = 1 << 13;

/// The best spatial split of a set: a plane at `pos` across `axis`, its SAH
/// cost (in `find_split`'s units) and the references each side will hold.
#[derive(Clone, Copy, Debug)]
pub(super) struct SpatialSplit {
    pub axis: usize,
    pub pos: f32,
    pub cost: f32,
    pub left: usize,
    pub right: usize,
}

/// The slab boundaries of each axis: `pos[axis][k]` for `k` in `0..=BINS`,
/// increasing, from the set's box's low side to its high side exactly.
struct Grid {
    /// Slabs per axis (at most `BINS`); `pos[a][nb]` is the high side.
    nb: usize,
    pos: [[f32; BINS + 1]; 3],
    lo: Vec4,
    scale: Vec4,
}

impl Grid {
    fn new(bounds: &Box4, nb: usize) -> Grid {
        let mut pos = [[0.0; BINS + 1]; 3];
        let ext = bounds.hi - bounds.lo;
        let mut scale = Vec4::ZERO;
        for a in 0..3 {
            for (k, p) in pos[a][..nb].iter_mut().enumerate() {
                *p = bounds.lo[a] + ext[a] * (k as f32 / nb as f32);
            }
            pos[a][nb] = bounds.hi[a];
            scale[a] = if ext[a] > 0.0 { nb as f32 / ext[a] } else { 0.0 };
        }
        Grid { nb, pos, lo: bounds.lo, scale }
    }

    /// The slabs a box from `lo` to `hi` on `axis` spans: the first is the
    /// last slab starting at or below `lo`, the last the first slab ending
    /// at or above `hi`. The guesses from the scale are corrected against
    /// the positions themselves, so the partition (which compares with the
    /// positions) agrees with the binning exactly.
    #[inline]
    fn range(&self, axis: usize, lo: f32, hi: f32) -> (usize, usize) {
        let p = &self.pos[axis];
        let last = self.nb - 1;
        let guess = |x: f32| (((x - self.lo[axis]) * self.scale[axis]).max(0.0) as usize).min(last);
        let mut b0 = guess(lo);
        while b0 > 0 && p[b0] > lo {
            b0 -= 1;
        }
        while b0 < last && p[b0 + 1] <= lo {
            b0 += 1;
        }
        let mut b1 = guess(hi);
        while b1 > 0 && p[b1] >= hi {
            b1 -= 1;
        }
        while b1 < last && p[b1 + 1] < hi {
            b1 += 1;
        }
        (b0, b1.max(b0))
    }
}

/// Per axis and slab: the union of the clipped pieces' boxes, how many
/// references start (`entry`) and end (`exit`) there.
#[derive(Clone, Copy)]
struct Bins {
    boxes: [[Box4; BINS]; 3],
    entry: [[u32; BINS]; 3],
    exit: [[u32; BINS]; 3],
}

impl Bins {
    const EMPTY: Bins = Bins { boxes: [[Box4::EMPTY; BINS]; 3], entry: [[0; BINS]; 3], exit: [[0; BINS]; 3] };

    fn fill(refs: &[PrimRef], prims: &PrimTable, grid: &Grid) -> Bins {
        let mut bins = Bins::EMPTY;
        for r in refs {
            let mut tri = None;
            for axis in 0..3 {
                if grid.scale[axis] == 0.0 {
                    continue;
                }
                let (b0, b1) = grid.range(axis, r.lo[axis], r.hi[axis]);
                bins.entry[axis][b0] += 1;
                bins.exit[axis][b1] += 1;
                if b0 == b1 {
                    bins.boxes[axis][b0] = bins.boxes[axis][b0].union(Box4::of(r));
                    continue;
                }
                let v = *tri.get_or_insert_with(|| triangle(prims, r));
                let boxes = &mut bins.boxes[axis];
                chop(v.as_ref(), r, axis, &grid.pos[axis], b0, b1, |k, piece| boxes[k] = boxes[k].union(piece));
            }
        }
        bins
    }

    fn merge(mut self, o: Bins) -> Bins {
        for a in 0..3 {
            for k in 0..BINS {
                self.boxes[a][k] = self.boxes[a][k].union(o.boxes[a][k]);
                self.entry[a][k] += o.entry[a][k];
                self.exit[a][k] += o.exit[a][k];
            }
        }
        self
    }
}

/// The vertices of `r`'s triangle, or `None` for a sphere (whose pieces
/// are its box's).
#[inline]
fn triangle(prims: &PrimTable, r: &PrimRef) -> Option<[Vec3; 3]> {
    let p = prims.get(r.index());
    (!p.is_sphere()).then_some(p.v)
}

/// `clip` for every slab from `b0` to `b1` at once, handing each slab's
/// piece to `emit(k, piece)`: each plane's crossing points are found once
/// and shared by the slabs on both sides, so a reference spanning many
/// slabs costs one pass over its edges per plane rather than two per slab.
#[inline]
fn chop(v: Option<&[Vec3; 3]>, r: &PrimRef, axis: usize, pos: &[f32; BINS + 1], b0: usize, b1: usize, mut emit: impl FnMut(usize, Box4)) {
    let Some(v) = v else {
        for k in b0..=b1 {
            if let Some(piece) = within(Box4::of(r), r, axis, pos[k], pos[k + 1]) {
                emit(k, piece);
            }
        }
        return;
    };
    // The crossing points at the slab's low plane; a piece of a triangle
    // (an earlier spatial split's reference) may cross `b0`'s too.
    let mut low = plane_cut(v, axis, pos[b0]);
    for k in b0..=b1 {
        let high = plane_cut(v, axis, pos[k + 1]);
        if let Some(piece) = within(slab_piece(v, axis, pos[k], pos[k + 1], low, high), r, axis, pos[k], pos[k + 1]) {
            emit(k, piece);
        }
        low = high;
    }
}

/// The box of the points where triangle `v`'s edges cross the plane at
/// `c` on `axis` (strictly; a vertex on the plane is `slab_piece`'s).
#[inline]
fn plane_cut(v: &[Vec3; 3], axis: usize, c: f32) -> Box4 {
    let mut cut = Box4::EMPTY;
    for i in 0..3 {
        let (p, q) = (v[i], v[(i + 1) % 3]);
        if (p[axis] < c && q[axis] > c) || (p[axis] > c && q[axis] < c) {
            let (lo, hi) = crossing(p, q, axis, c);
            cut.grow(lo);
            cut.grow(hi);
        }
    }
    cut
}

/// The box of triangle `v`'s part between `a` and `b` on `axis`, given
/// the planes' cuts (`plane_cut`): the corners of that polygon are the cut
/// points and the vertices between the planes.
#[inline]
fn slab_piece(v: &[Vec3; 3], axis: usize, a: f32, b: f32, cut_a: Box4, cut_b: Box4) -> Box4 {
    let mut piece = cut_a.union(cut_b);
    for p in v {
        if p[axis] >= a && p[axis] <= b {
            piece.grow(p.extend(0.0));
        }
    }
    piece
}

/// Where edge `p`-`q` crosses the plane at `c` on `axis` (it must cross
/// strictly), as a box: exact on the axis, widened by 2^-20 of the edge's
/// coordinates (several ulps) off it, where the point is rounded.
#[inline]
fn crossing(p: Vec3, q: Vec3, axis: usize, c: f32) -> (Vec4, Vec4) {
    let t = (c - p[axis]) / (q[axis] - p[axis]);
    let x = p + (q - p) * t;
    let pad = p.abs().max(q.abs()) * (1.0 / (1 << 20) as f32);
    let (mut lo, mut hi) = (x - pad, x + pad);
    lo[axis] = c;
    hi[axis] = c;
    (lo.extend(0.0), hi.extend(0.0))
}

/// `piece` inside `r`'s box and between `a` and `b` on `axis`; `None`
/// when that is empty.
#[inline]
fn within(piece: Box4, r: &PrimRef, axis: usize, a: f32, b: f32) -> Option<Box4> {
    let mut lo = piece.lo.max(r.lo);
    let mut hi = piece.hi.min(r.hi);
    lo[axis] = lo[axis].max(a);
    hi[axis] = hi[axis].min(b);
    let empty = lo.cmpgt(hi).bitmask() & 0b111 != 0;
    (!empty).then_some(Box4 { lo, hi })
}

/// The box of the part of triangle `v` (or, for `None`, of `r`'s box)
/// between `a` and `b` on `axis`, inside `r`'s box; `None` when empty.
fn clip(v: Option<&[Vec3; 3]>, r: &PrimRef, axis: usize, a: f32, b: f32) -> Option<Box4> {
    let piece = match v {
        None => Box4::of(r),
        Some(v) => slab_piece(v, axis, a, b, plane_cut(v, axis, a), plane_cut(v, axis, b)),
    };
    within(piece, r, axis, a, b)
}

/// The best spatial split of `refs` (bounded by `bounds`), costed as
/// `find_split` costs object splits (`scale`, `parent_area`); `None` when
/// no plane leaves both sides smaller than the set.
pub(super) fn find(refs: &[PrimRef], prims: &PrimTable, bounds: &Box4, scale: f32, parent_area: f32) -> Option<SpatialSplit> {
    let n = refs.len();
    let grid = Grid::new(bounds, bins_for(n));
    let nb = grid.nb;
    let bins = if n > PARALLEL {
        refs.par_chunks(CHUNK).map(|c| Bins::fill(c, prims, &grid)).reduce(|| Bins::EMPTY, Bins::merge)
    } else {
        Bins::fill(refs, prims, &grid)
    };
    let mut best: Option<SpatialSplit> = None;
    for axis in 0..3 {
        if grid.scale[axis] == 0.0 {
            continue;
        }
        let mut right_cost = [0.0f32; BINS];
        let mut right_n = [0usize; BINS];
        let (mut acc, mut cnt) = (Box4::EMPTY, 0usize);
        for k in (1..nb).rev() {
            acc = acc.union(bins.boxes[axis][k]);
            cnt += bins.exit[axis][k] as usize;
            right_n[k] = cnt;
            right_cost[k] = if cnt > 0 { acc.half_area_scaled(scale) * blocks(cnt) } else { 0.0 };
        }
        let (mut acc, mut cnt) = (Box4::EMPTY, 0usize);
        for k in 0..nb - 1 {
            acc = acc.union(bins.boxes[axis][k]);
            cnt += bins.entry[axis][k] as usize;
            let (nl, nr) = (cnt, right_n[k + 1]);
            if nl == 0 || nr == 0 || nl >= n || nr >= n {
                continue;
            }
            let cost = TRAVERSAL_COST + (acc.half_area_scaled(scale) * blocks(nl) + right_cost[k + 1]) / parent_area;
            if best.map_or(true, |b| cost < b.cost) {
                best = Some(SpatialSplit { axis, pos: grid.pos[axis][k + 1], cost, left: nl, right: nr });
            }
        }
    }
    best
}

/// Apply split `s` to the set `refs[..n]`, whose slice reaches to the end
/// of its spare room: references left of the plane (or crossing it, as the
/// piece on the left) go to the front, those right of it (or the crossing
/// ones' right pieces) to a run starting at the returned index, and the
/// spare room left over is shared between the sides in proportion to their
/// sizes. Returns `(left count, right start, right count)`.
pub(super) fn apply(refs: &mut [PrimRef], n: usize, prims: &PrimTable, s: &SpatialSplit) -> (usize, usize, usize) {
    let (axis, pos) = (s.axis, s.pos);
    // Dutch-flag partition of refs[..n] into [left | both | right]; these
    // tests agree with `Grid::range`'s slabs at the plane.
    let side = |r: &PrimRef| -> u8 {
        if r.lo[axis] >= pos {
            2
        } else if r.hi[axis] <= pos {
            0
        } else {
            1
        }
    };
    let (mut lt, mut i, mut gt) = (0, 0, n);
    while i < gt {
        match side(&refs[i]) {
            0 => {
                refs.swap(lt, i);
                lt += 1;
                i += 1;
            }
            2 => {
                gt -= 1;
                refs.swap(i, gt);
            }
            _ => i += 1,
        }
    }
    let (n_left_only, n_both) = (lt, gt - lt);
    let (nl, nr) = (lt + n_both, n - gt + n_both);
    assert!(nl + nr <= refs.len(), "spatial split past the reference budget");
    let spare = refs.len() - nl - nr;
    let right_start = nl + (spare as u64 * nl as u64 / (nl + nr) as u64) as usize;
    refs.copy_within(gt..n, right_start + n_both);
    for k in 0..n_both {
        let r = refs[n_left_only + k];
        let v = triangle(prims, &r);
        // A side the clipped triangle misses by rounding keeps the box's
        // own part on that side (never empty: the box crosses the plane).
        let left = clip(v.as_ref(), &r, axis, r.lo[axis], pos).unwrap_or_else(|| clip(None, &r, axis, r.lo[axis], pos).unwrap());
        let right = clip(v.as_ref(), &r, axis, pos, r.hi[axis]).unwrap_or_else(|| clip(None, &r, axis, pos, r.hi[axis]).unwrap());
        refs[n_left_only + k] = r.with_box(left);
        refs[right_start + k] = r.with_box(right);
    }
    (nl, right_start, nr)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;

    fn b(lo: [f32; 3], hi: [f32; 3]) -> Box4 {
        Box4 { lo: Vec3::from(lo).extend(0.0), hi: Vec3::from(hi).extend(0.0) }
    }

    /// A triangle's pieces between planes hold every point of the triangle
    /// in that slab (sampled densely), and their axis sides are the planes.
    #[test]
    fn clipped_pieces_hold_the_triangle_between_the_planes() {
        let v = [Vec3::new(-1.0, 0.1, 3.0), Vec3::new(7.0, -2.0, 1.0e3), Vec3::new(2.5, 9.0, -4.0)];
        let mut bb = Aabb::from_point(v[0]);
        bb.grow(v[1]);
        bb.grow(v[2]);
        let r = PrimRef::new(&bb, 7);
        for axis in 0..3 {
            let (lo, hi) = (bb.min[axis], bb.max[axis]);
            let cuts: Vec<f32> = (0..=10).map(|k| lo + (hi - lo) * k as f32 / 10.0).collect();
            for w in cuts.windows(2) {
                let piece = clip(Some(&v), &r, axis, w[0], w[1]).expect("the triangle spans every slab of its box");
                assert!(piece.lo[axis] >= w[0] && piece.hi[axis] <= w[1]);
                for i in 0..=200 {
                    for j in 0..=200 - i {
                        let (u, t) = (i as f32 / 200.0, j as f32 / 200.0);
                        let p = v[0] + (v[1] - v[0]) * u + (v[2] - v[0]) * t;
                        if p[axis] > w[0] && p[axis] < w[1] {
                            let p4 = p.extend(0.0);
                            assert!(p4.cmpge(piece.lo).bitmask() & 7 == 7 && p4.cmple(piece.hi).bitmask() & 7 == 7, "axis {axis} slab {w:?}: {p} outside");
                        }
                    }
                }
            }
        }
    }

    /// `chop` gives every slab the piece `clip` gives it, with the
    /// triangle's vertices on planes and off them, for the whole triangle
    /// and for pieces of it that it crosses the boxes of (where `chop` once
    /// missed the cut at the box's own side).
    #[test]
    fn chop_equals_clip_slab_by_slab() {
        let grid = Grid::new(&b([0.0, -3.0, -5.0], [16.0, 12.0, 1.0e3]), BINS);
        let tris = [
            [Vec3::new(0.5, 0.1, 3.0), Vec3::new(15.2, -2.0, 1.0e3), Vec3::new(2.5, 9.0, -4.0)],
            [Vec3::new(3.0, 0.0, 0.0), Vec3::new(9.0, 1.0, 2.0), Vec3::new(5.0, 11.0, 7.0)],
        ];
        for v in tris {
            let mut bb = Aabb::from_point(v[0]);
            bb.grow(v[1]);
            bb.grow(v[2]);
            let whole = PrimRef::new(&bb, 3);
            // Also pieces of the triangle, whose boxes it crosses: an earlier
            // spatial split's references.
            let pieces_of = |axis: usize, a: f32, b: f32| whole.with_box(clip(Some(&v), &whole, axis, a, b).unwrap());
            for (r, axis) in [whole, pieces_of(0, 4.3, 12.0), pieces_of(1, -1.0, 5.5), pieces_of(2, 1.5, 600.0)].into_iter().flat_map(|r| (0..3).map(move |a| (r, a))) {
                let (b0, b1) = grid.range(axis, r.lo[axis], r.hi[axis]);
                let mut pieces = [None; BINS];
                chop(Some(&v), &r, axis, &grid.pos[axis], b0, b1, |k, p| pieces[k] = Some((p.lo, p.hi)));
                for k in b0..=b1 {
                    let one = clip(Some(&v), &r, axis, grid.pos[axis][k], grid.pos[axis][k + 1]);
                    assert_eq!(pieces[k], one.map(|p| (p.lo, p.hi)), "axis {axis} slab {k}");
                }
            }
        }
    }

    /// A long diagonal triangle crossing the plane is referenced on both
    /// sides with boxes much smaller than its own; references wholly on
    /// one side move as they are, and the spare room is shared.
    #[test]
    fn apply_duplicates_crossing_triangles_with_their_pieces() {
        let shapes = vec![crate::scene::Shape::Mesh(crate::scene::TriangleMesh {
            positions: vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(10.0, 10.0, 0.0), Vec3::new(10.0, 10.1, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(8.0, 8.0, 0.0), Vec3::new(9.0, 8.0, 0.0), Vec3::new(9.0, 9.0, 0.0)],
            triangles: vec![[0, 1, 2], [3, 4, 5], [6, 7, 8]],
            normals: Vec::new(),
        })];
        let prims = PrimTable::new(&shapes);
        let mut refs: Vec<PrimRef> = (0..3).map(|i| PrimRef::new(&prims.get(i).bounds(), i)).collect();
        refs.resize(7, refs[0]);
        let s = SpatialSplit { axis: 0, pos: 5.0, cost: 0.0, left: 2, right: 2 };
        let (nl, rs, nr) = apply(&mut refs, 3, &prims, &s);
        assert_eq!((nl, nr), (2, 2));
        assert_eq!(rs, 2 + 3 * 2 / 4, "the 3 spare references are shared in proportion");
        let left: Vec<u32> = refs[..nl].iter().map(|r| r.index()).collect();
        let right: Vec<u32> = refs[rs..rs + nr].iter().map(|r| r.index()).collect();
        assert!(left.contains(&0) && left.contains(&1) && right.contains(&0) && right.contains(&2));
        for r in refs[..nl].iter().chain(&refs[rs..rs + nr]).filter(|r| r.index() == 0) {
            let e = r.hi - r.lo;
            assert!(e.x <= 5.0 + 1e-4 && e.y <= 5.2, "piece {:?}..{:?} not clipped", r.lo, r.hi);
        }
        assert!(refs[..nl].iter().all(|r| r.hi.x <= 5.0) && refs[rs..rs + nr].iter().all(|r| r.lo.x >= 5.0));
    }

    /// The binning's slab ranges agree with the partition's tests at every
    /// plane, including boxes that touch a plane or are flat on it.
    #[test]
    fn slab_ranges_agree_with_the_planes() {
        for nb in [4, 8, BINS] {
            let grid = Grid::new(&b([0.1, 0.0, 0.0], [1.7, 1.0, 1.0]), nb);
            let p = &grid.pos[0][..=nb];
            let mut xs: Vec<f32> = p.to_vec();
            xs.extend(p.iter().map(|x| x.next_up()));
            xs.extend(p.iter().map(|x| x.next_down()));
            xs.retain(|x| *x >= p[0] && *x <= p[nb]);
            for &lo in &xs {
                for &hi in xs.iter().filter(|h| **h >= lo) {
                    let (b0, b1) = grid.range(0, lo, hi);
                    assert!(b0 <= b1 && b1 < nb);
                    for (k, &pos) in p.iter().enumerate().take(nb).skip(1) {
                        let (goes_left, goes_right) = if lo >= pos { (false, true) } else if hi <= pos { (true, false) } else { (true, true) };
                        assert_eq!(goes_left, b0 < k, "{nb} slabs: lo {lo} hi {hi} plane {k}");
                        assert_eq!(goes_right, b1 >= k, "{nb} slabs: lo {lo} hi {hi} plane {k}");
                    }
                }
            }
        }
    }
}
