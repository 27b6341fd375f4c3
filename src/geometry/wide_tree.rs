//! The tree of a scene of more than a few dozen triangles: obvhs's binary tree (PLOC with
//! reinsertion, one triangle per leaf) collapsed into 8-wide nodes by the SAH dynamic programme
//! of Ylitie, Karras and Laine (2017, "Efficient incoherent ray traversal on GPUs through
//! compressed wide BVHs", §3.1), the one obvhs's own CWBVH conversion runs. Here the child boxes
//! are the binary tree's own, rounded outward to f32 once, where obvhs's conversion quantised
//! them to 8 bits of their node (up to ²⁄₂₅₅ of its size larger), and each node's subtree is laid
//! out after it, so a ray's walk down one branch reads nearby memory.
//!
//! The programme: cost(n, i) is the least SAH cost of the binary subtree n given as at most i
//! children of one wide node, with A(n) its box's half area (relative to the root's),
//!   cost(n, 1) = min(A(n)·(C_LEAF + C_TRIANGLE·count(n)) as a leaf (count ≤ LEAF_MOST),
//!                    A(n)·C_NODE + split(n, 8)),
//!   cost(n, i) = min(cost(n, i − 1), split(n, i)),
//!   split(n, j) = min over 1 ≤ k < j of cost(left, k) + cost(right, j − k).

use obvhs::bvh2::Bvh2;

use super::bvh::{Bvh8, Node8, LEAF_MOST, MOST_LEVELS};

/// The relative costs of visiting a wide node, of visiting a leaf, and of each triangle in it.
/// A leaf's triangles are tested four at a time in lanes (`leaf4`) and their cache lines are
/// fetched together, so a leaf costs about what a node does whatever its count; the paper's
/// C_TRIANGLE = 0.3 a triangle and no cost a leaf, tuned for one triangle at a time, made 60 %
/// of the 1.3 M-triangle sphere's leaves single triangles (1.5 a leaf, 131 k nodes); these give
/// 2.4 a leaf with leaves of up to 4 (88 k nodes), more with up to 8, and a shallower tree
/// (raybench, C_LEAF 0.6–1.2 and C_TRIANGLE 0.02–0.05 measured alike within noise; an extra
/// cost for a leaf's second pass of lanes, 0.3, made no difference).
const C_NODE: f32 = 1.0;
const C_LEAF: f32 = 1.0;
const C_TRIANGLE: f32 = 0.03;

/// The triangles' leaf order (position → index given to obvhs) and the wide tree over
/// `bvh2`, a tree of one primitive per leaf; Err(levels) for a tree that would be deeper than
/// MOST_LEVELS. Real scenes' trees are ~10 levels deep; only a pathological input gets there
/// (a disk of 3·10⁴ segments or more, its sliver triangles all overlapping at the centre).
pub fn build(bvh2: &Bvh2, triangle_bytes: usize) -> Result<(Vec<usize>, Bvh8), usize> {
    let nodes = &bvh2.nodes;
    // Half areas relative to the root's, taken in f64: in f32 they overflow to ∞ for
    // coordinates past 10¹⁹, and with every cost ∞ the programme would choose nothing.
    let half_area = |n: usize| {
        let d = (nodes[n].aabb.max - nodes[n].aabb.min).as_dvec3();
        d.x * d.y + d.y * d.z + d.z * d.x
    };
    let root_area = Some(half_area(0)).filter(|a| a.is_finite() && *a > 0.0).unwrap_or(1.0);
    let area = |n: usize| (half_area(n) / root_area) as f32;
    let leaf_cost = |n: usize, count: u32| area(n) * (C_LEAF + C_TRIANGLE * count as f32);
    let mut count = vec![0u32; nodes.len()];
    let mut cost = vec![[f32::INFINITY; 8]; nodes.len()];
    let mut leaf = vec![false; nodes.len()];
    // Children before parents, without recursion (a binary tree can be deep).
    let mut todo = vec![(0usize, false)];
    while let Some((n, children_done)) = todo.pop() {
        match children(bvh2, n) {
            None => {
                // obvhs is asked for one triangle a leaf (`max_prims_per_leaf: 1`): its PLOC makes
                // leaves of one and its reinsertion moves whole nodes.
                count[n] = nodes[n].prim_count;
                assert!(count[n] <= LEAF_MOST, "a binary leaf of {} triangles", count[n]);
                leaf[n] = true;
                cost[n] = [leaf_cost(n, count[n]); 8];
            }
            Some((l, r)) if children_done => {
                count[n] = count[l] + count[r];
                let split = |j: usize| best_split(&cost, l, r, j).1;
                let as_leaf = if count[n] <= LEAF_MOST { leaf_cost(n, count[n]) } else { f32::INFINITY };
                let as_node = area(n) * C_NODE + split(8);
                // The count test too, so that no pattern of costs (ties at ∞ before the areas
                // were made relative) can make a subtree of more than 4 a leaf.
                leaf[n] = count[n] <= LEAF_MOST && as_leaf <= as_node;
                let mut row = [as_leaf.min(as_node); 8];
                for i in 2..=8 {
                    row[i - 1] = row[i - 2].min(split(i));
                }
                cost[n] = row;
            }
            Some((l, r)) => todo.extend([(n, true), (l, false), (r, false)]),
        }
    }
    let mut wide = Collapse {
        bvh2,
        count: &count,
        cost: &cost,
        leaf: &leaf,
        nodes: Vec::new(),
        order: Vec::with_capacity(bvh2.primitive_indices.len()),
    };
    let root_children = if leaf[0] { vec![0] } else { wide.split(0, 8) };
    wide.node(&root_children, 1)?;
    Ok((wide.order, Bvh8::from_nodes(wide.nodes, triangle_bytes)))
}

/// The two children of binary node n, or None for a leaf.
fn children(bvh2: &Bvh2, n: usize) -> Option<(usize, usize)> {
    let node = &bvh2.nodes[n];
    let first = node.first_index as usize;
    (node.prim_count == 0).then_some((first, first + 1))
}

/// The best share of j ≥ 2 children between binary children l and r: (k for l, j − k for r)
/// with the least cost(l, k) + cost(r, j − k), the first such k, and that cost.
fn best_split(cost: &[[f32; 8]], l: usize, r: usize, j: usize) -> (usize, f32) {
    let mut best = (1, f32::INFINITY);
    for k in 1..j {
        let total = cost[l][k - 1] + cost[r][j - k - 1];
        if total < best.1 {
            best = (k, total);
        }
    }
    best
}

struct Collapse<'a> {
    bvh2: &'a Bvh2,
    count: &'a [u32],
    cost: &'a [[f32; 8]],
    leaf: &'a [bool],
    nodes: Vec<Node8>,
    order: Vec<usize>,
}

impl Collapse<'_> {
    /// The binary nodes that inner node n is given as, at most j of them (j ≥ 2), as the
    /// programme chose: its children's shares are found again from their cost rows.
    fn split(&self, n: usize, j: usize) -> Vec<usize> {
        let (l, r) = children(self.bvh2, n).expect("only an inner binary node is split");
        let (k, _) = best_split(self.cost, l, r, j);
        let mut out = self.part(l, k);
        out.extend(self.part(r, j - k));
        out
    }

    /// Node n as at most i nodes: itself, or split into the fewest that reach its least cost.
    /// Each step splits into fewer than before, so this recurses at most 8 deep.
    fn part(&self, n: usize, i: usize) -> Vec<usize> {
        let row = &self.cost[n];
        match (1..=i).find(|&m| row[m - 1] == row[i - 1]) {
            Some(m) if m > 1 => self.split(n, m),
            _ => vec![n],
        }
    }

    /// A wide node with the binary nodes `kids` as its children, those the programme made
    /// leaves with their triangles (appended to the order), the rest as wide nodes of their own
    /// laid out after it. Err(level) once the tree passes MOST_LEVELS.
    fn node(&mut self, kids: &[usize], level: usize) -> Result<u32, usize> {
        if level > MOST_LEVELS {
            return Err(level);
        }
        let at = self.nodes.len();
        self.nodes.push(Node8::EMPTY);
        for (slot, &k) in kids.iter().enumerate() {
            let child = if self.leaf[k] {
                let first = self.order.len() as u32;
                self.triangles_of(k);
                Node8::leaf(first, self.count[k])
            } else {
                let grandchildren = self.split(k, 8);
                self.node(&grandchildren, level + 1)?
            };
            // obvhs's boxes are exact unions of the padded triangles' (`PaddedTriangle`); one
            // more ulp outward each way is a margin beyond that padding, at no cost.
            self.nodes[at].set_child_box(slot, child, &self.bvh2.nodes[k].aabb, 0.0);
        }
        Ok(at as u32)
    }

    /// Appends the triangles under node n (at most LEAF_MOST) in the binary tree's order.
    fn triangles_of(&mut self, n: usize) {
        let node = &self.bvh2.nodes[n];
        if node.prim_count == 0 {
            let first = node.first_index as usize;
            self.triangles_of(first);
            self.triangles_of(first + 1);
        } else {
            let at = node.first_index as usize;
            let prims = &self.bvh2.primitive_indices[at..at + node.prim_count as usize];
            self.order.extend(prims.iter().map(|&p| p as usize));
        }
    }
}
