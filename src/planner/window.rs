//! The look-ahead window's elements, with what the walks back through it have checked of them
//! and still holds.
//!
//! A walk of the backward pass through the window ([`Planner::merge_back`]) ends with a check
//! that the marks of the earlier passes ([`Pending::pass_mark`]) chain down to the speed the
//! plan has settled ([`Planner::marks_come_down`]). The links of that chain below the element
//! the pass stands at depend only on the elements themselves (their marks, caps, limits,
//! lengths and pairs) and on the settled speed, and between two such walks the elements
//! changed lie near the window's end. The window keeps how far from its start the chain is
//! known to hold ([`Window::marks_ok_below`]), and every way to change an element lowers
//! that, so a walk stops there with the same answer: on 200 000 tiny spiral chords
//! (`benches/planner.rs`) the links looked at fell from 8.4 M (about 610 a walk, down to the
//! window's start) to 2.4 M.
//!
//! Reads go through [`Deref`] to the elements; changes only through the methods here, each of
//! which forgets the links the change may break.
//!
//! [`Planner::merge_back`]: super::Planner::merge_back
//! [`Planner::marks_come_down`]: super::Planner::marks_come_down

use std::collections::VecDeque;
use std::collections::vec_deque;
use std::ops::{Deref, Index, IndexMut, RangeFrom, RangeTo};

use super::Pending;

/// The window's elements, oldest first, and the links of the chain of marks known to hold.
#[derive(Debug, Clone)]
pub(super) struct Window {
    elements: VecDeque<Pending>,
    /// With `marks_settled_mm_s`: every link `j` below this (the mark of element `j` ending
    /// within the start of the mark of `j + 1`, still its element's, the cap after it within
    /// its speed limit) holds, and the first element's mark starts at least at
    /// `marks_settled_mm_s` (0: nothing known).
    links_ok: usize,
    /// The settled speed the chain was checked against.
    marks_settled_mm_s: f64,
}

impl Window {
    /// An empty window with room for `capacity` elements.
    pub(super) fn with_capacity(capacity: usize) -> Window {
        Window {
            elements: VecDeque::with_capacity(capacity),
            links_ok: 0,
            marks_settled_mm_s: 0.0,
        }
    }

    /// Forgets the links that a change of element `i` may break: its own, and the one before,
    /// which reads its mark's start and its cap.
    fn touch(&mut self, i: usize) {
        self.links_ok = self.links_ok.min(i.saturating_sub(1));
    }

    /// How many links from the window's start are known to hold where the plan has settled
    /// at `settled_mm_s` (see `Window::links_ok`); 0 where nothing is known.
    pub(super) fn marks_ok_below(&self, settled_mm_s: f64) -> usize {
        if self.marks_settled_mm_s == settled_mm_s {
            self.links_ok
        } else {
            0
        }
    }

    /// Records that the links below `below` hold, and that the first element's mark starts
    /// at least at `settled_mm_s`.
    pub(super) fn set_marks_ok(&mut self, below: usize, settled_mm_s: f64) {
        self.links_ok = below;
        self.marks_settled_mm_s = settled_mm_s;
    }

    /// The last element, to change.
    pub(super) fn back_mut(&mut self) -> Option<&mut Pending> {
        self.touch(self.elements.len().saturating_sub(1));
        self.elements.back_mut()
    }

    /// Element `i`, to change.
    pub(super) fn get_mut(&mut self, i: usize) -> Option<&mut Pending> {
        self.touch(i);
        self.elements.get_mut(i)
    }

    /// The elements from `range.start` on, to change.
    pub(super) fn range_mut(&mut self, range: RangeFrom<usize>) -> vec_deque::IterMut<'_, Pending> {
        self.touch(range.start);
        self.elements.range_mut(range)
    }

    /// Adds `p` at the window's end.
    pub(super) fn push_back(&mut self, p: Pending) {
        self.touch(self.elements.len());
        self.elements.push_back(p);
    }

    /// Removes the elements before `range.end` (settled): every index moves, and the chain's
    /// first link changes (it is checked against the settled speed), so nothing is kept.
    pub(super) fn drain(&mut self, range: RangeTo<usize>) -> vec_deque::Drain<'_, Pending> {
        self.links_ok = 0;
        self.elements.drain(range)
    }
}

impl Deref for Window {
    type Target = VecDeque<Pending>;

    fn deref(&self) -> &VecDeque<Pending> {
        &self.elements
    }
}

impl Index<usize> for Window {
    type Output = Pending;

    fn index(&self, i: usize) -> &Pending {
        &self.elements[i]
    }
}

impl IndexMut<usize> for Window {
    fn index_mut(&mut self, i: usize) -> &mut Pending {
        self.touch(i);
        &mut self.elements[i]
    }
}
