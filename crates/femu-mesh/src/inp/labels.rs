//! Node and element labels to indices.

use std::collections::HashMap;

/// Empty slot of the direct table.
const EMPTY: u32 = u32::MAX;

/// Labels are looked up in a direct table while they stay below this many times the number of
/// labels so far (plus a start): decks number their nodes and elements 1..N, sometimes with
/// gaps or an offset per part, so the table stays a few times N at most. Other labels (negative,
/// or far apart) go to a hash map.
const DENSE_FACTOR: i64 = 8;
const DENSE_START: i64 = 1 << 16;

/// The labels of a deck's nodes (or elements) and their indices, in a direct table for the
/// usual compact numbering and a hash map for the rest. Hashing each of the paper-scale
/// deck's 51 000 labels (inserted once, looked up again for every element, set member and
/// load) took a fifth of reading the deck.
#[derive(Default)]
pub(super) struct LabelMap {
    dense: Vec<u32>,
    sparse: HashMap<i64, usize>,
    len: usize,
}

impl LabelMap {
    /// Whether `label` belongs in the direct table (given the labels so far).
    fn dense_slot(&self, label: i64) -> Option<usize> {
        let limit = DENSE_START.max(DENSE_FACTOR * self.len as i64);
        (0..limit).contains(&label).then_some(label as usize)
    }

    /// Records `label` at `index`; `false` (and nothing changed) if the label is already there.
    pub(super) fn insert(&mut self, label: i64, index: usize) -> bool {
        if self.get(label).is_some() {
            return false;
        }
        match (self.dense_slot(label), u32::try_from(index)) {
            (Some(slot), Ok(i)) if i != EMPTY => {
                if slot >= self.dense.len() {
                    let grown = (slot + 1).max(2 * self.dense.len());
                    self.dense.resize(grown, EMPTY);
                }
                self.dense[slot] = i;
            }
            _ => {
                self.sparse.insert(label, index);
            }
        }
        self.len += 1;
        true
    }

    /// The index of `label`, if it was inserted.
    pub(super) fn get(&self, label: i64) -> Option<usize> {
        let dense = usize::try_from(label)
            .ok()
            .and_then(|slot| self.dense.get(slot))
            .filter(|&&i| i != EMPTY);
        match dense {
            Some(&i) => Some(i as usize),
            None if self.sparse.is_empty() => None,
            None => self.sparse.get(&label).copied(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Compact labels, labels far apart, negative labels, repeated labels, and a label that
    /// first lands in the hash map and later would fit the grown table: every label found at
    /// its index, and every repeat refused.
    #[test]
    fn finds_every_label_and_refuses_repeats() {
        let mut labels: Vec<i64> = (1..=5000).collect();
        labels.extend([-7, 0, 1_000_000_007, 70_000, i64::MAX, i64::MIN]);
        labels.extend(200_000..204_000);
        let mut map = LabelMap::default();
        for (i, &l) in labels.iter().enumerate() {
            assert!(map.insert(l, i), "label {l} refused");
        }
        // 70 000 went to the hash map (above the first limit, 65 536); with 9 006 labels the
        // limit has since grown past it.
        assert!(map.sparse.contains_key(&70_000));
        assert!(map.dense_slot(70_000).is_some());
        for (i, &l) in labels.iter().enumerate() {
            assert_eq!(map.get(l), Some(i), "label {l}");
            assert!(!map.insert(l, 99), "label {l} accepted twice");
            assert_eq!(map.get(l), Some(i), "label {l} changed by a refused insert");
        }
        for l in [5001, -8, 69_999, 204_000, 1_000_000_008] {
            assert_eq!(map.get(l), None, "label {l}");
        }
    }
}
