//! That a model's vertex lists name each vertex once, checked in linear (or n log n) time
//! without allocating, and the lookups the loader derives from them.
//!
//! Prescribed vertices: each handle lists its vertices in ascending order (as the trainer's
//! selections do), so a handle repeats none when it ascends strictly, two handles share none
//! when one merge of their lists finds no common vertex (a model has at most
//! [`MAX_HANDLES`]), and a vertex's handle slot is a binary search per handle.
//!
//! Strands: their slots are in strand order, which no ordering rule can make ascending, so
//! the loader derives [`Model::chain_order`], the position of each free vertex among the slots;
//! with it, "every free vertex exactly once" is one pass over the slots.

use core::cmp::Ordering;

use crate::model::{ascending, Model, Problem, MAX_HANDLES};

/// Marks a free vertex that no slot names while [`fill_chain_order`] runs.
pub(crate) const UNNAMED: u32 = u32::MAX;

impl<'a> Model<'a> {
    /// Each handle's vertices as a part of [`Model::handle_vertices`] (split by the lengths of
    /// [`Model::handles`]) with the slot of its first vertex; a part past the end of the list
    /// is empty (refused by validation).
    pub(crate) fn handle_lists(&self) -> impl Iterator<Item = (usize, &'a [u32])> + Clone + 'a {
        let all = self.handle_vertices();
        self.handles.iter().scan(0usize, move |next, h| {
            let first = *next;
            *next = first.saturating_add(h.vertices.len as usize);
            Some((first, all.get(first..*next).unwrap_or(&[])))
        })
    }

    /// Whether every handle lists its vertices in strictly ascending order.
    pub(crate) fn handle_lists_ascend(&self) -> bool {
        self.handle_lists().all(|(_, list)| ascending(list))
    }

    /// Whether no prescribed vertex is listed twice: every handle's list ascends and no two
    /// share a vertex. With more than [`MAX_HANDLES`] handles (refused by validation) only the
    /// order is checked.
    pub(crate) fn handle_vertices_distinct(&self) -> bool {
        if !self.handle_lists_ascend() {
            return false;
        }
        if self.handles.len() > MAX_HANDLES {
            return true;
        }
        let lists = self.handle_lists();
        !lists
            .clone()
            .enumerate()
            .any(|(i, (_, a))| lists.clone().skip(i + 1).any(|(_, b)| share_a_value(a, b)))
    }

    /// The handle slot of prescribed vertex `v` (a binary search in each handle's list).
    pub(crate) fn handle_slot(&self, v: u32) -> Option<u32> {
        self.handle_lists()
            .find_map(|(first, list)| list.binary_search(&v).ok().map(|i| (first + i) as u32))
    }

    /// What is wrong when the strands' slots do not name every free vertex exactly once, given
    /// that they name as many as there are: the field and problem ([`Model::chain_order`]
    /// does not give each slot its own position).
    pub(crate) fn chain_order_problem(&self, free: usize) -> Option<(&'static str, Problem)> {
        let order = self.chain_order.of(self.indices).unwrap_or(&[]);
        if order.len() != free {
            let found = order.len();
            return Some(("chain_order", Problem::Length { expected: free, found }));
        }
        let slots = || self.chains().flat_map(|c| c.slots.iter().copied());
        let (j, _) = slots().zip(0u32..).find(|&(j, p)| order.get(j as usize) != Some(&p))?;
        // The position `chain_order` gives `j` holds `j` as well: a slot repeats it.
        let named = order.get(j as usize).and_then(|&q| slots().nth(q as usize));
        let field = if named == Some(j) {
            "chains.slots"
        } else {
            "chain_order"
        };
        Some((field, Problem::Inconsistent))
    }
}

/// Writes into `order` (one entry per free vertex, all [`UNNAMED`]) the position among the
/// slots of the chain table `table` (see [`Model::chains`]) of each free vertex at the first
/// slot that names it. Slots out of range and records that do not fit are skipped (refused by
/// validation).
pub(crate) fn fill_chain_order(table: &[u32], order: &mut [u32]) {
    let (mut rest, mut position) = (table, 0u32);
    while let Some((&[_, _, n], tail)) = rest.split_first_chunk::<3>() {
        let Some((slots, tail)) = tail.split_at_checked(n as usize) else {
            return;
        };
        for &j in slots {
            if let Some(o) = order.get_mut(j as usize).filter(|o| **o == UNNAMED) {
                *o = position;
            }
            position = position.wrapping_add(1);
        }
        rest = tail;
    }
}

/// Whether the ascending lists `a` and `b` have a value in common (one merge).
fn share_a_value(a: &[u32], b: &[u32]) -> bool {
    let (mut a, mut b) = (a.iter().peekable(), b.iter().peekable());
    while let (Some(x), Some(y)) = (a.peek(), b.peek()) {
        match x.cmp(y) {
            Ordering::Less => {
                a.next();
            }
            Ordering::Greater => {
                b.next();
            }
            Ordering::Equal => return true,
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merges_find_common_values() {
        assert!(share_a_value(&[1, 4, 9], &[2, 3, 9]));
        assert!(share_a_value(&[5], &[0, 5, 7]));
        assert!(!share_a_value(&[1, 4, 9], &[0, 2, 5, 10]));
        assert!(!share_a_value(&[], &[1]));
    }

    #[test]
    fn chain_order_names_first_positions() {
        // Two strands: slots [2, 0] and [1, 2, 3]; free vertex 3 named, 4 not.
        let table = [0, 1, 2, 2, 0, 0, 1, 3, 1, 2, 3];
        let mut order = [UNNAMED; 5];
        fill_chain_order(&table, &mut order);
        assert_eq!(order, [1, 2, 0, 4, UNNAMED]);
        // A record longer than the table stops the walk; slots out of range are skipped.
        let mut order = [UNNAMED; 2];
        fill_chain_order(&[0, 1, 2, 9, 1, 0, 1, 5, 0], &mut order);
        assert_eq!(order, [UNNAMED, 1]);
    }
}
