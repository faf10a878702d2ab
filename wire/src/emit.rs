//! [`Emit`]: the one way a part hands on what it makes.
//!
//! Every layer makes something and passes it on: the segmenter a foot's frames, the stance
//! pipeline a terrain decision per step, the node service its outputs, a capture its steps,
//! a component the frames it sends (`protocol::component::Outbox`), the lock-step bus
//! every frame it carries. Each takes `&mut (impl Emit<T> + ?Sized)` (or `&mut dyn Emit<T>`), so the
//! caller chooses where it goes: a closure (`|item| ...`), a `Vec` that collects, or the
//! component's outbox, without a callback shape per layer.
//!
//! ```
//! use presrs_wire::emit::Emit;
//! fn count_to(n: u32, out: &mut (impl Emit<u32> + ?Sized)) {
//!     for i in 1..=n { out.emit(i); }
//! }
//! let mut seen = Vec::new();
//! count_to(3, &mut seen);
//! let mut sum = 0;
//! count_to(3, &mut |i| sum += i);
//! assert_eq!((seen, sum), (vec![1, 2, 3], 6));
//! ```
//!
//! Emitting never fails and never blocks: a sink that can fill (a queue to another thread)
//! counts what it drops itself. On the hot path the sinks are closures and buffers kept
//! between calls, which allocate nothing once grown.

/// Where a part puts what it makes, one item at a time. See the [module docs](self).
pub trait Emit<T> {
    /// Takes one item.
    fn emit(&mut self, item: T);
}

/// Any closure taking the item. `FnMut` is a fundamental trait, so this and the impls below
/// do not overlap.
impl<T, F: FnMut(T)> Emit<T> for F {
    fn emit(&mut self, item: T) {
        self(item)
    }
}

/// Collects, oldest first.
#[cfg(feature = "alloc")]
impl<T> Emit<T> for alloc::vec::Vec<T> {
    fn emit(&mut self, item: T) {
        self.push(item)
    }
}
