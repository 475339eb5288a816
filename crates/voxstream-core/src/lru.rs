//! Least-recently-used slot allocation shared by the node pool and the brick pool.
//!
//! GigaVoxels [P09] §5 ("Cache management"): both pools are LRU caches; a ray's report refreshes a slot, allocation
//! takes the oldest slot, and a slot used during the current frame is never recycled (the renderer may still point
//! at it). Slots are integers; the list is intrusive (`prev`/`next` arrays), so touching and allocating are O(1).

const NONE: u32 = u32::MAX;

/// Where an allocated slot came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Allocation {
    /// A slot never used before, or freed explicitly.
    Fresh(u32),
    /// The least recently used slot; the caller must detach its old owner.
    Recycled(u32),
}

impl Allocation {
    /// The slot index.
    pub fn slot(self) -> u32 {
        match self {
            Allocation::Fresh(s) | Allocation::Recycled(s) => s,
        }
    }
}

/// Fixed-capacity set of slots ordered by last use.
#[derive(Debug, Clone)]
pub struct LruSlots {
    capacity: u32,
    /// Slots handed out so far (the high-water mark; `0..grown` exist).
    grown: u32,
    prev: Vec<u32>,
    next: Vec<u32>,
    stamp: Vec<u32>,
    is_linked: Vec<bool>,
    /// Most recently used end.
    head: u32,
    /// Least recently used end.
    tail: u32,
    free: Vec<u32>,
    linked_count: u32,
}

/// Most slots [`LruSlots::allocate_avoiding`] looks at, oldest first, for one it may recycle: bounds the work of one
/// allocation when the caller wants to keep many old slots.
pub const RECYCLE_SCAN: usize = 64;

/// Bytes of bookkeeping per slot (`prev`, `next`, `stamp`, `is_linked`), counted in the memory budget.
pub const LRU_BYTES_PER_SLOT: usize = 4 + 4 + 4 + 1;

impl LruSlots {
    /// An empty set able to hold `capacity` slots. Memory grows with use, up to the capacity.
    pub fn new(capacity: u32) -> LruSlots {
        LruSlots {
            capacity,
            grown: 0,
            prev: Vec::new(),
            next: Vec::new(),
            stamp: Vec::new(),
            is_linked: Vec::new(),
            head: NONE,
            tail: NONE,
            free: Vec::new(),
            linked_count: 0,
        }
    }

    /// Maximum number of slots.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Slots currently in use.
    pub fn len(&self) -> u32 {
        self.linked_count
    }

    /// Whether no slot is in use.
    pub fn is_empty(&self) -> bool {
        self.linked_count == 0
    }

    /// Number of slot indices ever handed out (`0..high_water()` are valid indices).
    pub fn high_water(&self) -> u32 {
        self.grown
    }

    /// Whether `slot` is in use.
    pub fn is_in_use(&self, slot: u32) -> bool {
        self.is_linked.get(slot as usize).copied().unwrap_or(false)
    }

    /// Frame at which `slot` was last used.
    pub fn stamp(&self, slot: u32) -> u32 {
        self.stamp[slot as usize]
    }

    /// Takes a slot: a free one if any, else the least recently used one if it was not used at `frame`.
    /// Returns `None` when every slot was used during `frame`. The slot is marked used at `frame`.
    pub fn allocate(&mut self, frame: u32) -> Option<Allocation> {
        self.allocate_avoiding(frame, |_| false).map(|(allocation, _)| allocation)
    }

    /// As [`LruSlots::allocate`], but a slot to recycle is the least recently used one among the oldest
    /// [`RECYCLE_SCAN`] not used at `frame` for which `keep` is false. When `keep` holds for all of them, the oldest
    /// is recycled all the same, and the second value is `true` (the caller's wish yielded to the capacity).
    pub fn allocate_avoiding(&mut self, frame: u32, mut keep: impl FnMut(u32) -> bool) -> Option<(Allocation, bool)> {
        let mut yielded = false;
        let allocation = if let Some(slot) = self.free.pop() {
            Allocation::Fresh(slot)
        } else if self.grown < self.capacity {
            let slot = self.grown;
            self.grown += 1;
            self.prev.push(NONE);
            self.next.push(NONE);
            self.stamp.push(0);
            self.is_linked.push(false);
            Allocation::Fresh(slot)
        } else if self.tail != NONE && self.stamp[self.tail as usize] < frame {
            let slot = self.oldest_not_kept(frame, &mut keep).unwrap_or_else(|| {
                yielded = true;
                self.tail
            });
            self.unlink(slot);
            Allocation::Recycled(slot)
        } else {
            return None;
        };
        let slot = allocation.slot();
        self.link_front(slot);
        self.stamp[slot as usize] = frame;
        Some((allocation, yielded))
    }

    /// The oldest of the [`RECYCLE_SCAN`] least recently used slots not used at `frame` that `keep` lets go.
    pub fn oldest_not_kept(&self, frame: u32, mut keep: impl FnMut(u32) -> bool) -> Option<u32> {
        self.iter_oldest_first()
            .take(RECYCLE_SCAN)
            .take_while(|&slot| self.stamp[slot as usize] < frame)
            .find(|&slot| !keep(slot))
    }

    /// Marks `slot` used at `frame` (moves it to the most-recent end).
    pub fn touch(&mut self, slot: u32, frame: u32) {
        if !self.is_in_use(slot) {
            return;
        }
        self.stamp[slot as usize] = frame;
        if self.head != slot {
            self.unlink(slot);
            self.link_front(slot);
        }
    }

    /// Returns `slot` to the free list.
    pub fn release(&mut self, slot: u32) {
        if self.is_in_use(slot) {
            self.unlink(slot);
            self.free.push(slot);
        }
    }

    /// Slots from least to most recently used (for tests and diagnostics).
    pub fn iter_oldest_first(&self) -> impl Iterator<Item = u32> + '_ {
        let mut cursor = self.tail;
        std::iter::from_fn(move || {
            (cursor != NONE).then(|| {
                let slot = cursor;
                cursor = self.prev[slot as usize];
                slot
            })
        })
    }

    fn link_front(&mut self, slot: u32) {
        let s = slot as usize;
        self.prev[s] = NONE;
        self.next[s] = self.head;
        if self.head != NONE {
            self.prev[self.head as usize] = slot;
        }
        self.head = slot;
        if self.tail == NONE {
            self.tail = slot;
        }
        self.is_linked[s] = true;
        self.linked_count += 1;
    }

    fn unlink(&mut self, slot: u32) {
        let s = slot as usize;
        let (p, n) = (self.prev[s], self.next[s]);
        if p != NONE {
            self.next[p as usize] = n;
        } else {
            self.head = n;
        }
        if n != NONE {
            self.prev[n as usize] = p;
        } else {
            self.tail = p;
        }
        self.prev[s] = NONE;
        self.next[s] = NONE;
        self.is_linked[s] = false;
        self.linked_count -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn recycles_the_oldest_slot_not_used_this_frame() {
        let mut lru = LruSlots::new(3);
        for frame in 1..=3 {
            assert!(matches!(lru.allocate(frame), Some(Allocation::Fresh(_))));
        }
        lru.touch(0, 4);
        // Slot 1 (stamp 2) is now the oldest.
        assert_eq!(lru.allocate(5), Some(Allocation::Recycled(1)));
        // Everything was used at frame 5 or later? Slots: 2 (stamp 3), 0 (4), 1 (5).
        assert_eq!(lru.allocate(5), Some(Allocation::Recycled(2)));
        assert_eq!(lru.allocate(5), Some(Allocation::Recycled(0)));
        assert_eq!(lru.allocate(5), None, "all slots used this frame: nothing to recycle");
    }

    #[test]
    fn released_slots_are_reused_first() {
        let mut lru = LruSlots::new(2);
        lru.allocate(1);
        lru.allocate(1);
        lru.release(0);
        assert_eq!(lru.len(), 1);
        assert_eq!(lru.allocate(1), Some(Allocation::Fresh(0)));
    }

    proptest! {
        #[test]
        fn list_stays_consistent(ops in proptest::collection::vec((0u8..3, 0u32..16), 0..200)) {
            let mut lru = LruSlots::new(8);
            let mut frame = 1;
            for (op, arg) in ops {
                match op {
                    0 => { lru.allocate(frame); }
                    1 => lru.touch(arg % 8, frame),
                    _ => { lru.release(arg % 8); frame += 1; }
                }
                let order: Vec<u32> = lru.iter_oldest_first().collect();
                prop_assert_eq!(order.len() as u32, lru.len());
                prop_assert!(lru.len() <= lru.capacity());
                // Stamps never decrease from oldest to newest.
                prop_assert!(order.windows(2).all(|w| lru.stamp(w[0]) <= lru.stamp(w[1])));
            }
        }
    }
}
