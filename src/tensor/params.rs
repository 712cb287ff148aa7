//! The parameter store: every learnable tensor (and every non-learnable buffer such as
//! batch-norm running statistics) of a model, by id and by unique name. Layers hold
//! [`ParamId`]s; the optimiser and checkpoints work on the whole store; gradients
//! come back from the tape in a [`Grads`] indexed by the same ids.

use super::tensor::Tensor;
use crate::{Error, Result};

/// Index of a tensor in a [`ParamStore`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ParamId(pub usize);

/// Whether the optimiser updates a stored tensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    /// Learnable: receives gradients, updated by the optimiser.
    Trainable,
    /// State that is saved but not learned (batch-norm running mean/variance).
    Buffer,
}

#[derive(Clone, Debug)]
struct Entry {
    name: String,
    kind: ParamKind,
    value: Tensor,
}

/// All parameters and buffers of a model, in creation order.
#[derive(Clone, Debug, Default)]
pub struct ParamStore {
    entries: Vec<Entry>,
}

impl ParamStore {
    /// An empty store.
    pub fn new() -> ParamStore {
        ParamStore::default()
    }

    /// Adds a tensor under a unique `name`.
    ///
    /// # Errors
    /// `Error::InvalidInput` when the name is already taken or empty.
    pub fn add(&mut self, name: &str, kind: ParamKind, value: Tensor) -> Result<ParamId> {
        if name.is_empty() {
            return Err(Error::invalid("parameter name is empty"));
        }
        if self.find(name).is_some() {
            return Err(Error::invalid(format!("duplicate parameter name '{name}'")));
        }
        self.entries.push(Entry { name: name.to_string(), kind, value });
        Ok(ParamId(self.entries.len() - 1))
    }

    /// The id of the tensor called `name`.
    pub fn find(&self, name: &str) -> Option<ParamId> {
        self.entries.iter().position(|e| e.name == name).map(ParamId)
    }

    /// Number of stored tensors.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// All ids, in creation order.
    pub fn ids(&self) -> impl Iterator<Item = ParamId> {
        (0..self.entries.len()).map(ParamId)
    }

    /// The value of `id`.
    ///
    /// # Panics
    /// When `id` does not come from this store.
    pub fn get(&self, id: ParamId) -> &Tensor {
        &self.entries[id.0].value
    }

    /// The value of `id`, mutable (shape fixed).
    ///
    /// # Panics
    /// When `id` does not come from this store.
    pub fn get_mut(&mut self, id: ParamId) -> &mut Tensor {
        &mut self.entries[id.0].value
    }

    /// Replaces the value of `id` by a tensor of the same shape.
    ///
    /// # Errors
    /// `Error::Shape` when the shapes differ.
    pub fn set(&mut self, id: ParamId, value: Tensor) -> Result<()> {
        let e = &mut self.entries[id.0];
        if e.value.shape() != value.shape() {
            return Err(Error::Shape {
                op: "ParamStore::set",
                msg: format!("'{}' is {}, got {}", e.name, e.value.shape(), value.shape()),
            });
        }
        e.value = value;
        Ok(())
    }

    /// The name of `id`.
    pub fn name(&self, id: ParamId) -> &str {
        &self.entries[id.0].name
    }

    /// The kind of `id`.
    pub fn kind(&self, id: ParamId) -> ParamKind {
        self.entries[id.0].kind
    }

    /// Number of learnable scalars (sum of the element counts of trainable tensors).
    pub fn num_trainable(&self) -> usize {
        self.entries.iter().filter(|e| e.kind == ParamKind::Trainable).map(|e| e.value.len()).sum()
    }
}

/// Gradients of the trainable parameters, indexed by [`ParamId`]; `None` where a
/// parameter received none. The tape accumulates into it (`+=`), so several
/// backward passes sum up until [`Grads::zero`].
#[derive(Clone, Debug, Default)]
pub struct Grads {
    g: Vec<Option<Tensor>>,
}

impl Grads {
    /// Empty gradients.
    pub fn new() -> Grads {
        Grads::default()
    }

    /// The gradient of `id`, if any was accumulated.
    pub fn get(&self, id: ParamId) -> Option<&Tensor> {
        self.g.get(id.0).and_then(|x| x.as_ref())
    }

    /// Drops every gradient (next backward starts from zero).
    pub fn zero(&mut self) {
        self.g.clear();
    }

    /// Adds `t` to the gradient of `id` (taking ownership when it is the first).
    ///
    /// # Errors
    /// `Error::Shape` when `t` differs in size from an existing gradient.
    pub fn accumulate(&mut self, id: ParamId, t: Tensor) -> Result<()> {
        if self.g.len() <= id.0 {
            self.g.resize(id.0 + 1, None);
        }
        match &mut self.g[id.0] {
            Some(x) => x.add_assign(&t),
            slot => {
                *slot = Some(t);
                Ok(())
            }
        }
    }

    /// Sum of squares of all gradients (for monitoring), in f64.
    pub fn norm_sq(&self) -> f64 {
        self.g.iter().flatten().flat_map(|t| t.data()).map(|&v| v as f64 * v as f64).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_grads_accumulate() {
        let mut s = ParamStore::new();
        let a = s.add("a", ParamKind::Trainable, Tensor::zeros(&[2]).unwrap()).unwrap();
        assert!(s.add("a", ParamKind::Buffer, Tensor::zeros(&[1]).unwrap()).is_err());
        assert_eq!(s.find("a"), Some(a));
        assert!(s.set(a, Tensor::zeros(&[3]).unwrap()).is_err());
        let mut g = Grads::new();
        g.accumulate(a, Tensor::new(&[2], vec![1.0, 2.0]).unwrap()).unwrap();
        g.accumulate(a, Tensor::new(&[2], vec![1.0, 2.0]).unwrap()).unwrap();
        assert_eq!(g.get(a).unwrap().data(), &[2.0, 4.0]);
    }
}
