//! The delayed-measurement buffer: one time-ordered queue type, keyed by
//! GPS time, for everything that waits for the filter's time horizon.
//!
//! PX4 EKF2 keeps each sensor's samples in a `RingBuffer` and pops the
//! first one older than the delayed fusion horizon; here the horizon is
//! the solution time (offline), the lagged time (fixed lag) or the time
//! of a stored state (delayed-state replay), and a `VecDeque` replaces the
//! fixed ring (the buffers are bounded by their horizon, not a size).

use std::collections::VecDeque;

use crate::filter::gnss::GnssFix;
use crate::ins::ImuSample;
use crate::time::GpsTime;

/// An item with a GPS time (the key of a [`DelayBuffer`]).
pub(in crate::fusion) trait Timed {
    fn time(&self) -> GpsTime;
}

impl Timed for GnssFix {
    /// The fix's time tag (its processing time may differ by τ̂).
    fn time(&self) -> GpsTime {
        self.time
    }
}

impl Timed for ImuSample {
    fn time(&self) -> GpsTime {
        self.time
    }
}

/// A time-ordered buffer keyed by GPS time. Items of equal time keep
/// their arrival order.
#[derive(Clone, Debug)]
pub(in crate::fusion) struct DelayBuffer<T> {
    items: VecDeque<T>,
}

impl<T> Default for DelayBuffer<T> {
    fn default() -> Self {
        DelayBuffer {
            items: VecDeque::new(),
        }
    }
}

impl<T: Timed> DelayBuffer<T> {
    /// Inserts in time order (after items of the same time).
    pub(in crate::fusion) fn insert(&mut self, item: T) {
        let t = item.time();
        let pos = self.count_through(t);
        self.items.insert(pos, item);
    }

    /// Appends in arrival order (IMU samples and states come in time
    /// order; the delayed-state log of fixes keeps their arrival order).
    pub(in crate::fusion) fn push_back(&mut self, item: T) {
        self.items.push_back(item);
    }

    /// Whether an item has exactly this time.
    pub(in crate::fusion) fn contains_time(&self, t: GpsTime) -> bool {
        self.items.iter().any(|x| x.time() == t)
    }

    /// The number of items up to and including `t` (items in time order).
    pub(in crate::fusion) fn count_through(&self, t: GpsTime) -> usize {
        self.items.partition_point(|x| x.time() <= t)
    }

    /// Drops the items up to and including `t` from the front.
    pub(in crate::fusion) fn drop_through(&mut self, t: GpsTime) {
        while self.items.front().is_some_and(|x| x.time() <= t) {
            self.items.pop_front();
        }
    }

    /// Drops items from the front while `stale` holds.
    pub(in crate::fusion) fn drop_while(&mut self, mut stale: impl FnMut(&T) -> bool) {
        while self.items.front().is_some_and(&mut stale) {
            self.items.pop_front();
        }
    }
}

impl<T> DelayBuffer<T> {
    pub(in crate::fusion) fn front(&self) -> Option<&T> {
        self.items.front()
    }

    pub(in crate::fusion) fn back(&self) -> Option<&T> {
        self.items.back()
    }

    pub(in crate::fusion) fn pop_front(&mut self) -> Option<T> {
        self.items.pop_front()
    }

    pub(in crate::fusion) fn len(&self) -> usize {
        self.items.len()
    }

    pub(in crate::fusion) fn iter(&self) -> std::collections::vec_deque::Iter<'_, T> {
        self.items.iter()
    }

    pub(in crate::fusion) fn truncate(&mut self, len: usize) {
        self.items.truncate(len);
    }
}

impl<T> std::ops::Index<usize> for DelayBuffer<T> {
    type Output = T;
    fn index(&self, i: usize) -> &T {
        &self.items[i]
    }
}

impl<'a, T> IntoIterator for &'a DelayBuffer<T> {
    type Item = &'a T;
    type IntoIter = std::collections::vec_deque::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.items.iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq)]
    struct Item(GpsTime, u8);

    impl Timed for Item {
        fn time(&self) -> GpsTime {
            self.0
        }
    }

    #[test]
    fn insert_keeps_time_order_and_arrival_order_within_a_time() {
        let t0 = GpsTime::default();
        let t = |s: f64| t0.add_seconds(s);
        let mut b = DelayBuffer::default();
        b.insert(Item(t(2.0), 0));
        b.insert(Item(t(1.0), 1));
        b.insert(Item(t(2.0), 2));
        b.insert(Item(t(1.5), 3));
        let order: Vec<u8> = b.iter().map(|x| x.1).collect();
        assert_eq!(order, [1, 3, 0, 2]);
        assert!(b.contains_time(t(1.5)));
        assert_eq!(b.count_through(t(1.5)), 2);
        b.drop_through(t(1.5));
        assert_eq!(b.front(), Some(&Item(t(2.0), 0)));
        b.drop_while(|x| x.1 == 0);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0], Item(t(2.0), 2));
    }
}
