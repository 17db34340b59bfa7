//! The wide collapse: obvhs's binary BVH turned into our 8-wide one, surface-area-optimal by
//! dynamic programming (Ylitie et al. 2017), with leaves of `Tri4` blocks.

use super::{Bvh, Node, Tri4, BLOCK_BITS, G, LEAF_BIT, LEAF_BLOCKS_MAX, LEAF_CAP, W};
use glam::{Vec3, Vec4};
use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;

/// How a binary subtree is laid out in a given number of slots of a wide node.
#[derive(Clone, Copy)]
enum Pick {
    /// One slot: a leaf with all its triangles.
    Leaf,
    /// One slot: a wide node of its own.
    Inner,
    /// The children share the slots, this many to the left one.
    Split(u8),
    /// One slot fewer does as well.
    Fewer,
}

/// Turns obvhs's binary BVH into our 8-wide one.
pub(super) struct Collapser<'a> {
    bvh2: &'a Bvh2,
    tris: &'a [[Vec3; 3]],
    valid: &'a [u32],
    /// Per binary node and slot budget (1..=W, index − 1): how its subtree is best laid out.
    pick: Vec<[Pick; W]>,
    /// Per binary node that becomes a wide node: slots of the W given to its left child.
    inner_split: Vec<u8>,
    nodes: Vec<Node>,
    blocks: Vec<Tri4>,
    /// Deepest chain of nodes made by `split_leaf` (extra traversal depth below a leaf).
    split_depth: usize,
}

impl<'a> Collapser<'a> {
    pub(super) fn new(bvh2: &'a Bvh2, tris: &'a [[Vec3; 3]], valid: &'a [u32], c_node: f32) -> Collapser<'a> {
        let n2 = &bvh2.nodes;
        // Preorder with an explicit stack (a degenerate build may be deep), then costs bottom-up.
        let mut order = Vec::with_capacity(n2.len());
        let mut st = vec![0u32];
        while let Some(i) = st.pop() {
            order.push(i);
            let nd = &n2[i as usize];
            if nd.prim_count == 0 {
                st.extend([nd.first_index, nd.first_index + 1]);
            }
        }
        let mut count = vec![0u32; n2.len()];
        let mut cost = vec![[0f32; W]; n2.len()];
        let mut pick = vec![[Pick::Leaf; W]; n2.len()];
        let mut inner_split = vec![0u8; n2.len()];
        for &i in order.iter().rev() {
            let nd = &n2[i as usize];
            let area = nd.aabb.half_area();
            let i = i as usize;
            if nd.prim_count > 0 {
                count[i] = nd.prim_count;
                cost[i] = [area * nd.prim_count.div_ceil(4) as f32; W];
                continue;
            }
            let (l, r) = (nd.first_index as usize, nd.first_index as usize + 1);
            count[i] = count[l] + count[r];
            let as_leaf = if count[i] <= LEAF_CAP { area * count[i].div_ceil(4) as f32 } else { f32::INFINITY };
            // Cheapest way to spread the subtree over j slots, j = 2..=W: k to the left child.
            let mut dist = [(f32::INFINITY, 0u8); W + 1];
            for (j, d) in dist.iter_mut().enumerate().skip(2) {
                for k in 1..j {
                    let c = cost[l][k - 1] + cost[r][j - k - 1];
                    if c < d.0 {
                        *d = (c, k as u8);
                    }
                }
            }
            let inner = area * c_node + dist[W].0;
            inner_split[i] = dist[W].1;
            (cost[i][0], pick[i][0]) = if as_leaf <= inner { (as_leaf, Pick::Leaf) } else { (inner, Pick::Inner) };
            for j in 2..=W {
                (cost[i][j - 1], pick[i][j - 1]) =
                    if dist[j].0 < cost[i][j - 2] { (dist[j].0, Pick::Split(dist[j].1)) } else { (cost[i][j - 2], Pick::Fewer) };
            }
        }
        Collapser { bvh2, tris, valid, pick, inner_split, nodes: Vec::new(), blocks: Vec::new(), split_depth: 0 }
    }

    /// Appends to `out` the binary nodes that represent the subtree under `n` in at most
    /// `slots` children of a wide node (the optimum found by `new`).
    fn collect(&self, n: u32, slots: usize, out: &mut Vec<u32>) {
        match self.pick[n as usize][slots - 1] {
            Pick::Leaf | Pick::Inner => out.push(n),
            Pick::Fewer => self.collect(n, slots - 1, out),
            Pick::Split(k) => {
                let f = self.bvh2.nodes[n as usize].first_index;
                self.collect(f, k as usize, out);
                self.collect(f + 1, slots - k as usize, out);
            }
        }
    }

    fn is_leaf(&self, i: u32) -> bool {
        matches!(self.pick[i as usize][0], Pick::Leaf)
    }

    pub(super) fn run(mut self) -> Bvh {
        // work: (binary node, wide node index, depth of the wide node)
        let mut work = Vec::new();
        let mut max_depth = 1;
        self.nodes.push(empty_node());
        if self.is_leaf(0) {
            let aabb = self.bvh2.nodes[0].aabb;
            let c = self.leaf(0);
            set_child(&mut self.nodes[0], 0, &aabb, c);
        } else {
            work.push((0u32, 0usize, 1usize));
        }
        while let Some((i2, wi, depth)) = work.pop() {
            max_depth = max_depth.max(depth);
            let nd = &self.bvh2.nodes[i2 as usize];
            let mut kids = Vec::with_capacity(W);
            let k = self.inner_split[i2 as usize] as usize;
            self.collect(nd.first_index, k, &mut kids);
            self.collect(nd.first_index + 1, W - k, &mut kids);
            for (slot, &k) in kids.iter().enumerate() {
                let aabb = self.bvh2.nodes[k as usize].aabb;
                let c = if self.is_leaf(k) {
                    self.leaf(k)
                } else {
                    self.nodes.push(empty_node());
                    let idx = self.nodes.len() - 1;
                    work.push((k, idx, depth + 1));
                    idx as u32
                };
                set_child(&mut self.nodes[wi], slot, &aabb, c);
            }
        }
        // Each level pushes at most W − 1 entries, plus one popped-and-refilled slot.
        let stack_need = (max_depth + self.split_depth) * (W - 1) + 1;
        Bvh::new(self.nodes, self.blocks, stack_need)
    }

    /// Leaf reference for the triangles under binary node `i`.
    fn leaf(&mut self, i: u32) -> u32 {
        let mut prims = Vec::new();
        let mut st = vec![i];
        while let Some(j) = st.pop() {
            let nd = &self.bvh2.nodes[j as usize];
            if nd.prim_count > 0 {
                let f = nd.first_index as usize;
                prims.extend_from_slice(&self.bvh2.primitive_indices[f..f + nd.prim_count as usize]);
            } else {
                st.extend([nd.first_index, nd.first_index + 1]);
            }
        }
        let first = self.blocks.len();
        for chunk in prims.chunks(4) {
            let mut blk = Tri4 { v: [[Vec4::ZERO; 3]; 3], id: [0; 4] };
            for lane in 0..4 {
                let p = chunk[lane.min(chunk.len() - 1)] as usize;
                for (vtx, pos) in self.tris[p].iter().enumerate() {
                    for axis in 0..3 {
                        blk.v[vtx][axis][lane] = pos[axis];
                    }
                }
                blk.id[lane] = self.valid[p];
            }
            self.blocks.push(blk);
        }
        let n = self.blocks.len() - first;
        // obvhs's PLOC leaves hold one triangle, so a leaf only exceeds the block limit if a
        // future obvhs makes large leaves; it then still works, split over several leaves
        // under a chain of nodes.
        if n <= LEAF_BLOCKS_MAX {
            return LEAF_BIT | (((n - 1) as u32) << BLOCK_BITS) | first as u32;
        }
        let aabb = self.bvh2.nodes[i as usize].aabb;
        self.split_leaf(first, n, &aabb, 1)
    }

    /// A node whose children share `aabb` and split `n` blocks starting at `first`.
    fn split_leaf(&mut self, first: usize, n: usize, aabb: &Aabb, depth: usize) -> u32 {
        self.split_depth = self.split_depth.max(depth);
        self.nodes.push(empty_node());
        let idx = self.nodes.len() - 1;
        let per = n.div_ceil(W);
        for (slot, start) in (first..first + n).step_by(per).enumerate() {
            let len = per.min(first + n - start);
            let c = if len <= LEAF_BLOCKS_MAX {
                LEAF_BIT | (((len - 1) as u32) << BLOCK_BITS) | start as u32
            } else {
                self.split_leaf(start, len, aabb, depth + 1)
            };
            set_child(&mut self.nodes[idx], slot, aabb, c);
        }
        idx as u32
    }
}

fn empty_node() -> Node {
    let inf = Vec4::INFINITY;
    Node { b: [[inf; G], [inf; G], [inf; G], [-inf; G], [-inf; G], [-inf; G]], child: [u32::MAX; W], valid: 0 }
}

fn set_child(node: &mut Node, slot: usize, aabb: &Aabb, c: u32) {
    let (g, l) = (slot / 4, slot % 4);
    for axis in 0..3 {
        node.b[axis][g][l] = aabb.min[axis];
        node.b[3 + axis][g][l] = aabb.max[axis];
    }
    node.child[slot] = c;
    node.valid |= 1 << slot;
}
