//! The open-list entry of the planners' searches (Hybrid A* and the waypoint
//! graph): a node and its priority f, popped smallest f first from `std`'s
//! max-heap `BinaryHeap`.

use std::cmp::Ordering;

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Open {
    pub f: f64,
    pub node: u32,
}

impl Eq for Open {}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        other.f.total_cmp(&self.f)
    }
}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BinaryHeap;

    #[test]
    fn pops_the_smallest_f_first() {
        let mut h: BinaryHeap<Open> = [3.0, 1.0, 2.0]
            .iter()
            .enumerate()
            .map(|(i, &f)| Open { f, node: i as u32 })
            .collect();
        assert_eq!(h.pop().map(|o| o.node), Some(1));
        assert_eq!(h.pop().map(|o| o.node), Some(2));
        assert_eq!(h.pop().map(|o| o.node), Some(0));
    }
}
