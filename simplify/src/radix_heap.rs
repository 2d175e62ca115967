//! A monotone priority queue over `u64` keys (the radix heap of Ahuja, Mehlhorn, Orlin and
//! Tarjan 1990), for the collapse order.
//!
//! Keys are non-negative `f64` costs as bits, whose integer order is their numeric order. A
//! radix heap needs extraction to be monotone; a key pushed below the last one popped is
//! raised to it, so it comes out next, which is exactly where a true min-heap would have put
//! it. Pushes are appends and each item moves between buckets only a few times, so the queue
//! stays cache-friendly where a binary heap of millions of entries does not.

/// The queue; `T` is the payload stored with each key.
#[derive(Debug)]
pub(crate) struct RadixHeap<T> {
    buckets: Vec<Vec<(u64, T)>>,
    last: u64,
    len: usize,
}

impl<T: Copy> Default for RadixHeap<T> {
    fn default() -> Self {
        Self {
            buckets: (0..65).map(|_| Vec::new()).collect(),
            last: 0,
            len: 0,
        }
    }
}

impl<T: Copy> RadixHeap<T> {
    /// Empties the queue and resets its floor to zero, keeping the buckets' memory.
    pub(crate) fn clear(&mut self) {
        self.buckets.iter_mut().for_each(Vec::clear);
        self.last = 0;
        self.len = 0;
    }

    fn bucket(&self, key: u64) -> usize {
        (64 - (key ^ self.last).leading_zeros()) as usize
    }

    /// Adds `item` with priority `key` (raised to the last key popped, if below it).
    pub(crate) fn push(&mut self, key: u64, item: T) {
        let key = key.max(self.last);
        let b = self.bucket(key);
        self.buckets[b].push((key, item));
        self.len += 1;
    }

    /// Removes an item with the smallest key.
    #[cfg(test)]
    pub(crate) fn pop(&mut self) -> Option<(u64, T)> {
        if self.len == 0 {
            return None;
        }
        if self.buckets[0].is_empty() {
            let i = self.buckets.iter().position(|b| !b.is_empty())?;
            let moved = std::mem::take(&mut self.buckets[i]);
            self.last = moved.iter().map(|&(k, _)| k).min().unwrap_or(self.last);
            for &(k, item) in &moved {
                let b = self.bucket(k);
                self.buckets[b].push((k, item));
            }
            // Give the emptied bucket its allocation back.
            let mut moved = moved;
            moved.clear();
            self.buckets[i] = moved;
        }
        self.len -= 1;
        self.buckets[0].pop()
    }

    /// Removes an item with the smallest key among those `valid` accepts, dropping every
    /// rejected item it meets. `valid` must reject an item for good once it rejects it (as a
    /// stale entry stays stale): then the order among the valid items is that of [`Self::pop`].
    /// Rejected items are also dropped in bulk whenever a bucket is redistributed, where the
    /// checks of a whole bucket run back to back (their memory accesses overlap) instead of
    /// one per pop.
    pub(crate) fn pop_valid(&mut self, valid: impl FnMut(&T) -> bool) -> Option<(u64, T)> {
        self.pop_valid_at_most(u64::MAX, valid)
    }

    /// [`Self::pop_valid`], but only an item whose key is at most `ceiling`: `None` when the
    /// smallest valid key is above it (that item stays queued).
    pub(crate) fn pop_valid_at_most(
        &mut self,
        ceiling: u64,
        mut valid: impl FnMut(&T) -> bool,
    ) -> Option<(u64, T)> {
        let key = self.peek_valid(&mut valid)?;
        if key > ceiling {
            return None;
        }
        self.len -= 1;
        self.buckets[0].pop()
    }

    /// The smallest key among the items `valid` accepts, dropping the rejected items it meets
    /// (as [`Self::pop_valid`]). The item stays queued, on top of bucket 0, where the next
    /// pop takes it.
    pub(crate) fn peek_valid(&mut self, mut valid: impl FnMut(&T) -> bool) -> Option<u64> {
        loop {
            match self.buckets[0].last() {
                // Every item of bucket 0 has the key `last`.
                Some((_, item)) if valid(item) => return Some(self.last),
                Some(_) => {
                    self.buckets[0].pop();
                    self.len -= 1;
                }
                None => {
                    let i = self.buckets.iter().position(|b| !b.is_empty())?;
                    let mut moved = std::mem::take(&mut self.buckets[i]);
                    let before = moved.len();
                    moved.retain(|(_, item)| valid(item));
                    self.len -= before - moved.len();
                    if let Some(min) = moved.iter().map(|&(k, _)| k).min() {
                        self.last = min;
                        for &(k, item) in &moved {
                            let b = self.bucket(k);
                            self.buckets[b].push((k, item));
                        }
                    }
                    moved.clear();
                    self.buckets[i] = moved;
                }
            }
        }
    }

    /// Every queued item with its key, in no particular order.
    pub(crate) fn items(&self) -> impl Iterator<Item = &[(u64, T)]> {
        self.buckets.iter().map(Vec::as_slice)
    }

    /// Number of queued items.
    pub(crate) fn len(&self) -> usize {
        self.len
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn pops_in_key_order_like_a_sorted_list(keys in prop::collection::vec(0u64..1 << 40, 0..300)) {
            let mut heap = RadixHeap::default();
            for (i, &k) in keys.iter().enumerate() {
                heap.push(k, i);
            }
            prop_assert_eq!(heap.len(), keys.len());
            let mut sorted = keys.clone();
            sorted.sort_unstable();
            let popped: Vec<u64> = std::iter::from_fn(|| heap.pop().map(|(k, _)| k)).collect();
            prop_assert_eq!(popped, sorted);
        }

        #[test]
        fn pop_valid_is_pop_without_the_rejected(keys in prop::collection::vec(0u64..1 << 40, 0..300)) {
            let (mut all, mut some) = (RadixHeap::default(), RadixHeap::default());
            for (i, &k) in keys.iter().enumerate() {
                all.push(k, i);
                some.push(k, i);
            }
            let expected: Vec<(u64, usize)> =
                std::iter::from_fn(|| all.pop()).filter(|&(_, i)| i % 3 != 0).collect();
            let got: Vec<(u64, usize)> = std::iter::from_fn(|| some.pop_valid(|&i| i % 3 != 0)).collect();
            let keys_of = |v: &[(u64, usize)]| v.iter().map(|p| p.0).collect::<Vec<_>>();
            prop_assert_eq!(keys_of(&got), keys_of(&expected));
            prop_assert_eq!(some.len(), 0);
        }

        #[test]
        fn a_key_below_the_floor_comes_out_next(first in 10u64..1000, low in 0u64..10) {
            let mut heap = RadixHeap::default();
            heap.push(first, 0);
            heap.push(first + 5, 1);
            prop_assert_eq!(heap.pop(), Some((first, 0)));
            heap.push(low, 2);
            prop_assert_eq!(heap.pop(), Some((first, 2)));
            prop_assert_eq!(heap.pop(), Some((first + 5, 1)));
        }
    }
}
