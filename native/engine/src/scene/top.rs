//! The top level of the scene hierarchy: a bounding-volume tree over instances (world boxes),
//! so that a receiver culls whole groups of objects below its horizon at once. Built when
//! instances are added; when instances move or meshes deform it is only refitted.

use crate::mesh::{box_centre, Vec3};

use super::clusters::{box_of, union, EMPTY_BOX, NO_CHILD};

#[derive(Clone, Copy, Debug)]
pub struct TopNode {
    pub children: [u32; 2],
    /// For a leaf, the instance.
    pub instance: u32,
}

pub struct TopTree {
    pub nodes: Vec<TopNode>,
    pub bounds: Vec<[Vec3; 2]>,
}

impl TopTree {
    /// Over the instances' world boxes.
    pub fn build(instance_bounds: &[[Vec3; 2]]) -> TopTree {
        let centres: Vec<Vec3> = instance_bounds.iter().map(box_centre).collect();
        let mut order: Vec<u32> = (0..instance_bounds.len() as u32).collect();
        let mut nodes = Vec::new();
        if !order.is_empty() {
            split(&centres, &mut order, &mut nodes);
        }
        let mut tree = TopTree { nodes, bounds: Vec::new() };
        tree.refit(instance_bounds);
        tree
    }

    pub fn refit(&mut self, instance_bounds: &[[Vec3; 2]]) {
        let mut bounds = vec![EMPTY_BOX; self.nodes.len()];
        for n in (0..self.nodes.len()).rev() {
            let node = self.nodes[n];
            bounds[n] = if node.children[0] == NO_CHILD {
                instance_bounds[node.instance as usize]
            } else {
                union(&bounds[node.children[0] as usize], &bounds[node.children[1] as usize])
            };
        }
        self.bounds = bounds;
    }
}

fn split(centres: &[Vec3], order: &mut [u32], nodes: &mut Vec<TopNode>) -> u32 {
    let id = nodes.len() as u32;
    nodes.push(TopNode { children: [NO_CHILD; 2], instance: NO_CHILD });
    if order.len() == 1 {
        nodes[id as usize].instance = order[0];
        return id;
    }
    let b = box_of(order.iter().map(|&i| centres[i as usize]));
    let axis = (0..3).max_by(|&i, &j| (b[1][i] - b[0][i]).total_cmp(&(b[1][j] - b[0][j]))).unwrap_or(0);
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&x, &y| centres[x as usize][axis].total_cmp(&centres[y as usize][axis]));
    let (left, right) = order.split_at_mut(mid);
    let l = split(centres, left, nodes);
    let r = split(centres, right, nodes);
    nodes[id as usize].children = [l, r];
    id
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_box_holds_every_instance_and_each_is_one_leaf() {
        let boxes: Vec<[Vec3; 2]> = (0..37).map(|i| [[i as f32, 0.0, 0.0], [i as f32 + 0.5, 1.0, 1.0]]).collect();
        let tree = TopTree::build(&boxes);
        assert_eq!(tree.bounds[0], [[0.0, 0.0, 0.0], [36.5, 1.0, 1.0]]);
        let mut leaves: Vec<u32> = tree.nodes.iter().filter(|n| n.children[0] == NO_CHILD).map(|n| n.instance).collect();
        leaves.sort();
        assert_eq!(leaves, (0..37).collect::<Vec<u32>>());
    }
}
