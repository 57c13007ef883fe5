//! A process-wide cache of the most recently used entries, for the builds that are slow
//! and repeat with the same inputs (the node materials of `alpha_step`, the single term's
//! calibrations). A `Vec` searched linearly: the caches hold tens of entries and a lookup
//! is nothing next to the build it saves.

/// At most `cap` entries, the most recently used last.
pub(crate) struct Recent<K, V> {
    cap: usize,
    entries: Vec<(K, V)>,
}

impl<K: PartialEq, V: Clone> Recent<K, V> {
    /// An empty cache of at most `cap` entries (`const`: usable in a `static Mutex`).
    pub(crate) const fn new(cap: usize) -> Self {
        Recent {
            cap,
            entries: Vec::new(),
        }
    }

    /// The value kept for `key`, now the most recently used.
    pub(crate) fn get(&mut self, key: &K) -> Option<V> {
        let i = self.entries.iter().position(|(k, _)| k == key)?;
        let hit = self.entries.remove(i);
        let v = hit.1.clone();
        self.entries.push(hit);
        Some(v)
    }

    /// Keep `value` for `key` unless one is kept already (two threads that built the same
    /// entry at once keep the first), dropping the least recently used when full.
    pub(crate) fn insert(&mut self, key: K, value: V) {
        if self.entries.iter().any(|(k, _)| *k == key) {
            return;
        }
        if self.entries.len() >= self.cap {
            self.entries.remove(0);
        }
        self.entries.push((key, value));
    }
}

#[cfg(test)]
mod tests {
    use super::Recent;

    #[test]
    fn keeps_the_most_recently_used() {
        let mut r = Recent::new(2);
        r.insert(1, "a");
        r.insert(2, "b");
        assert_eq!(r.get(&1), Some("a")); // 1 is now the most recent
        r.insert(3, "c"); // drops 2
        assert_eq!(r.get(&2), None);
        assert_eq!((r.get(&1), r.get(&3)), (Some("a"), Some("c")));
        r.insert(3, "d"); // kept already: the first stays
        assert_eq!(r.get(&3), Some("c"));
    }
}
