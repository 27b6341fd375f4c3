//! The tree of a scene of a few dozen triangles (a room, a box of blocks), built whole instead of
//! by obvhs: clusters merged bottom-up, each time the pair whose box grows least over its two
//! parts' (searched exhaustively: a lamp joins the ceiling it hangs under, a block's faces join
//! each other), then collapsed into 8-wide nodes by opening the largest child while a slot is
//! free (as Embree widens its binary trees). A triangle pair stays one leaf, so each wall of a
//! room is a flat leaf box under the root and each block a node of its own. obvhs's tree of the
//! Cornell box put half the back wall and the lamp into the tall block's node, a box spanning
//! half the room that most rays entered.
//!
//! Boxes are the triangles' padded bounds, widened (`PAD_OF_DIAGONAL`) so that the slab test's
//! rounding never drops a box that a ray's triangle hit lies in.

use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::Boundable;

use super::bvh::{Bvh8, Node8};
use super::PaddedTriangle;

/// Scenes of up to this many triangles get this tree (the exhaustive merge search is cubic).
pub const MOST_TRIANGLES: usize = 64;
/// The most triangles in a leaf: one pass of `leaf4`'s lanes.
const LEAF_MOST: u32 = 4;
/// Clusters of up to this many triangles are never opened: a quad stays one leaf.
const ATOM: u32 = 2;
/// Each box, over its triangles' padded bounds (`PaddedTriangle`: 10⁻⁵ of their coordinates),
/// is widened by this share of the scene's diagonal. The slab test's t errs by about an ulp of
/// the ray origin's coordinates and two of the distance travelled (the roundings of 1/d, of o/d
/// and of the fused multiply-add), so this covers rays from up to a thousand scene sizes away,
/// as the quantisation of obvhs's CWBVH boxes (up to ²⁄₂₅₅ of their node's size) did.
const PAD_OF_DIAGONAL: f64 = 1.0 / 4096.0;

struct Cluster {
    bounds: Aabb,
    count: u32,
    /// The two merged clusters, or the triangle of a single one.
    parts: Result<(usize, usize), usize>,
}

/// Half the surface area of a box (the growth criterion needs no factor 2).
fn area(b: &Aabb) -> f64 {
    b.half_area() as f64
}

/// The triangles' leaf order (position → index in `tris`) and the tree over them; None when
/// the scene is not small.
pub fn build(tris: &[[Vec3A; 3]], triangle_bytes: usize) -> Option<(Vec<usize>, Bvh8)> {
    if tris.is_empty() || tris.len() > MOST_TRIANGLES {
        return None;
    }
    let mut clusters: Vec<Cluster> = tris
        .iter()
        .enumerate()
        .map(|(i, t)| Cluster { bounds: PaddedTriangle(*t).aabb(), count: 1, parts: Err(i) })
        .collect();
    let mut active: Vec<usize> = (0..clusters.len()).collect();
    while active.len() > 1 {
        // The pair whose box grows least over its parts' own; ties to the first pair found, so
        // the tree depends on the triangles' order only.
        let mut best = (f64::INFINITY, 0, 1);
        for i in 0..active.len() {
            for j in i + 1..active.len() {
                let (a, b) = (&clusters[active[i]], &clusters[active[j]]);
                let growth = area(&a.bounds.union(&b.bounds)) - area(&a.bounds) - area(&b.bounds);
                if growth < best.0 {
                    best = (growth, i, j);
                }
            }
        }
        let (_, i, j) = best;
        let (a, b) = (&clusters[active[i]], &clusters[active[j]]);
        let merged =
            Cluster { bounds: a.bounds.union(&b.bounds), count: a.count + b.count, parts: Ok((active[i], active[j])) };
        clusters.push(merged);
        active[i] = clusters.len() - 1;
        active.swap_remove(j);
    }
    let pad = clusters[active[0]].bounds.diagonal().as_dvec3().length() * PAD_OF_DIAGONAL;
    let mut tree = Collapse { clusters: &clusters, pad, nodes: vec![], order: vec![] };
    let root = active[0];
    if clusters[root].count <= LEAF_MOST {
        // Too few triangles for an inner node of their own: a root holding one leaf.
        tree.node(&[root]);
    } else {
        tree.node_of(root);
    }
    Some((tree.order, Bvh8::from_nodes(tree.nodes, triangle_bytes)))
}

struct Collapse<'a> {
    clusters: &'a [Cluster],
    pad: f64,
    nodes: Vec<Node8>,
    order: Vec<usize>,
}

impl Collapse<'_> {
    /// A node for inner cluster `c`: its two parts, then the largest openable child replaced by
    /// its parts while a slot is free.
    fn node_of(&mut self, c: usize) -> u32 {
        let Ok((a, b)) = self.clusters[c].parts else { unreachable!("a leaf cluster has no node") };
        let mut kids = vec![a, b];
        while kids.len() < 8 {
            let open = (0..kids.len())
                .filter(|&k| self.clusters[kids[k]].count > ATOM)
                .max_by(|&x, &y| area(&self.clusters[kids[x]].bounds).total_cmp(&area(&self.clusters[kids[y]].bounds)));
            let Some(k) = open else { break };
            let Ok((a, b)) = self.clusters[kids[k]].parts else { unreachable!("clusters above ATOM are merged") };
            kids[k] = a;
            kids.insert(k + 1, b);
        }
        self.node(&kids)
    }

    /// A node with children `kids`: those of up to `LEAF_MOST` triangles as leaves (their
    /// triangles appended to the order), the rest as nodes of their own.
    fn node(&mut self, kids: &[usize]) -> u32 {
        let at = self.nodes.len();
        self.nodes.push(Node8::EMPTY);
        for (slot, &k) in kids.iter().enumerate() {
            let cluster = &self.clusters[k];
            let child = if cluster.count <= LEAF_MOST {
                let first = self.order.len() as u32;
                self.triangles_of(k);
                Node8::leaf(first, cluster.count)
            } else {
                self.node_of(k)
            };
            self.nodes[at].set_child_box(slot, child, &cluster.bounds, self.pad);
        }
        at as u32
    }

    fn triangles_of(&mut self, c: usize) {
        match self.clusters[c].parts {
            Ok((a, b)) => {
                self.triangles_of(a);
                self.triangles_of(b);
            }
            Err(t) => self.order.push(t),
        }
    }
}
