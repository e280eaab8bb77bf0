//! A least-recently-used order over slab-allocated nodes: the replacement scheme of the paper's
//! §5.2 ("We use a least-recently-used (LRU) cache replacement scheme"). Every operation is
//! O(1), so a cache lookup holds its tier's lock only briefly.
//!
//! Nodes live in one `Vec` and link to each other by `u32` index, not by pointer: no `unsafe`,
//! one allocation for the whole list, and 8 bytes of links per node. Freed nodes are reused. The
//! tier keeps each entry itself in its node (not behind a pointer), so a resident entry is one
//! slab slot and one index bucket, and no allocation of its own unless the entry has one.

/// "No node": the end of the list, or of the free list.
const NIL: u32 = u32::MAX;

struct Node<T> {
    /// `None` while the node is on the free list.
    value: Option<T>,
    /// Towards the most recently used end.
    prev: u32,
    /// Towards the least recently used end.
    next: u32,
}

/// Values in recency order: the front is the most recently used, the back the least.
pub(crate) struct LruList<T> {
    nodes: Vec<Node<T>>,
    head: u32,
    tail: u32,
    /// The first free node; free nodes chain through `next`.
    free: u32,
    len: usize,
}

impl<T> Default for LruList<T> {
    fn default() -> Self {
        Self { nodes: Vec::new(), head: NIL, tail: NIL, free: NIL, len: 0 }
    }
}

impl<T> LruList<T> {
    /// Values in the list.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Adds `value` as the most recently used and returns its node index, which stays valid
    /// until the value is removed.
    ///
    /// # Panics
    /// If the list would hold `u32::MAX` nodes (hundreds of gigabytes of entries).
    pub(crate) fn push_front(&mut self, value: T) -> u32 {
        let i = if self.free != NIL {
            let i = self.free;
            let node = &mut self.nodes[i as usize];
            self.free = node.next;
            node.value = Some(value);
            i
        } else {
            let i = u32::try_from(self.nodes.len()).ok().filter(|&i| i != NIL).expect("LRU list holds more than u32::MAX - 1 entries");
            self.nodes.push(Node { value: Some(value), prev: NIL, next: NIL });
            i
        };
        self.link_front(i);
        self.len += 1;
        i
    }

    /// The value at node `i`.
    ///
    /// # Panics
    /// If `i` is not a live node.
    pub(crate) fn get(&self, i: u32) -> &T {
        self.nodes[i as usize].value.as_ref().expect("LRU node is live")
    }

    /// The value at node `i`, to change.
    ///
    /// # Panics
    /// If `i` is not a live node.
    pub(crate) fn get_mut(&mut self, i: u32) -> &mut T {
        self.nodes[i as usize].value.as_mut().expect("LRU node is live")
    }

    /// Marks node `i` as the most recently used.
    pub(crate) fn touch(&mut self, i: u32) {
        if self.head != i {
            self.unlink(i);
            self.link_front(i);
        }
    }

    /// Removes node `i` and returns its value.
    ///
    /// # Panics
    /// If `i` is not a live node.
    pub(crate) fn remove(&mut self, i: u32) -> T {
        self.unlink(i);
        let node = &mut self.nodes[i as usize];
        let value = node.value.take().expect("LRU node is live");
        node.next = self.free;
        node.prev = NIL;
        self.free = i;
        self.len -= 1;
        value
    }

    /// Removes and returns the least recently used value.
    #[cfg(test)]
    pub(crate) fn pop_back(&mut self) -> Option<T> {
        (self.tail != NIL).then(|| self.remove(self.tail))
    }

    /// The node of the least recently used value.
    pub(crate) fn back(&self) -> Option<u32> {
        (self.tail != NIL).then_some(self.tail)
    }

    /// Live nodes and their values, in slab order (not recency order).
    pub(crate) fn live(&self) -> impl Iterator<Item = (u32, &T)> + '_ {
        self.nodes.iter().enumerate().filter_map(|(i, n)| n.value.as_ref().map(|v| (i as u32, v)))
    }

    /// Heap bytes of the slab (all nodes it has room for, live or not).
    pub(crate) fn heap_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<Node<T>>()
    }

    /// Values from the most to the least recently used.
    #[cfg(test)]
    pub(crate) fn iter(&self) -> impl Iterator<Item = &T> + '_ {
        let mut i = self.head;
        std::iter::from_fn(move || {
            (i != NIL).then(|| {
                let node = &self.nodes[i as usize];
                i = node.next;
                node.value.as_ref().expect("LRU node is live")
            })
        })
    }

    fn link_front(&mut self, i: u32) {
        let old_head = self.head;
        {
            let node = &mut self.nodes[i as usize];
            node.prev = NIL;
            node.next = old_head;
        }
        if old_head != NIL {
            self.nodes[old_head as usize].prev = i;
        } else {
            self.tail = i;
        }
        self.head = i;
    }

    fn unlink(&mut self, i: u32) {
        let (prev, next) = {
            let node = &self.nodes[i as usize];
            (node.prev, node.next)
        };
        if prev != NIL {
            self.nodes[prev as usize].next = next;
        } else {
            self.head = next;
        }
        if next != NIL {
            self.nodes[next as usize].prev = prev;
        } else {
            self.tail = prev;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn order(l: &LruList<char>) -> String {
        l.iter().collect()
    }

    #[test]
    fn push_touch_pop_keep_recency_order() {
        let mut l = LruList::default();
        let a = l.push_front('a');
        let b = l.push_front('b');
        let c = l.push_front('c');
        assert_eq!(order(&l), "cba");
        l.touch(a);
        assert_eq!(order(&l), "acb");
        l.touch(a); // already the front: a no-op
        assert_eq!(order(&l), "acb");
        l.touch(b);
        assert_eq!(order(&l), "bac");
        assert_eq!(l.pop_back(), Some('c'));
        assert_eq!(order(&l), "ba");
        assert_eq!(*l.get(b), 'b');
        assert_eq!(l.len(), 2);
        let _ = c;
    }

    #[test]
    fn remove_from_middle_and_reuse_slots() {
        let mut l = LruList::default();
        let ids: Vec<u32> = "abcde".chars().map(|ch| l.push_front(ch)).collect();
        assert_eq!(l.remove(ids[2]), 'c');
        assert_eq!(order(&l), "edba");
        assert_eq!(l.remove(ids[4]), 'e'); // the head
        assert_eq!(l.remove(ids[0]), 'a'); // the tail
        assert_eq!(order(&l), "db");
        // Freed nodes are reused before the slab grows.
        let f = l.push_front('f');
        let g = l.push_front('g');
        assert!(f == ids[0] || f == ids[2] || f == ids[4]);
        assert!(g == ids[0] || g == ids[2] || g == ids[4]);
        assert_eq!(l.nodes.len(), 5);
        assert_eq!(order(&l), "gfdb");
        assert_eq!(l.len(), 4);
    }

    #[test]
    fn pop_back_drains_in_lru_order() {
        let mut l = LruList::default();
        for ch in "xyz".chars() {
            l.push_front(ch);
        }
        let drained: String = std::iter::from_fn(|| l.pop_back()).collect();
        assert_eq!(drained, "xyz");
        assert_eq!(l.len(), 0);
        assert_eq!(l.pop_back(), None);
        assert_eq!((l.head, l.tail), (NIL, NIL));
    }
}
