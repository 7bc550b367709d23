//! Small-network kernels: plain `f32` vectors, hand-written backward passes.
//!
//! At these sizes (64-64 layers, minibatches of 100) candle's per-op overhead made a
//! PPO minibatch step 5.4× slower than these kernels (`cargo bench -p schrl --bench
//! ppo`); the planner's hand-written update and the neural SDF use them too.
//!
//! * [`mlp`] — a tanh MLP over one flat parameter vector, forward and backward.
//! * [`adam`] — Adam with global gradient-norm clipping over a flat vector; it knows
//!   nothing of the model.

pub mod adam;
pub mod mlp;
