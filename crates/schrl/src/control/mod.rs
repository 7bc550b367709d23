//! The goal-conditioned low-level controller (paper §3.3, App. K): PPO over
//! vectorised environments of any robot.
//!
//! Read top to bottom: [`policy`] (Gaussian actor and critic on [`crate::nn::mlp`]),
//! [`normalize`] (running statistics), [`ppo`] (GAE, the clipped losses, the update
//! with [`crate::nn::adam`]), [`trainer`] (rollouts with random goals, evaluation).
//! Saving and resuming is [`crate::store::controller`]'s.

pub mod normalize;
pub mod policy;
pub mod ppo;
pub mod trainer;

pub use policy::ActorCritic;
pub use ppo::{PpoConfig, PpoLearner};
pub use trainer::{
    ControlConfig, ControlError, ControlMetrics, ControlTrainer, Controller, NearGoals, TrackDefaults,
};
