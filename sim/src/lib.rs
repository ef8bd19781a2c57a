//! The simulated collaborative work-cell of workcell.
//!
//! A [`Scenario`] (TOML) describes the cell; [`CellModel`] is what it builds and never
//! changes; [`CellState`] is the running world, advanced by [`step`]. The same seed gives
//! bit-identical states after any number of steps on the same machine.
//!
//! ```
//! use workcell_sim::{CellModel, CellState, RobotCommand, Scenario, step};
//!
//! let scenario = Scenario { seed: 3, ..Scenario::default() };
//! let model = CellModel::new(&scenario, std::path::Path::new("inline.toml"))?;
//! let mut state = CellState::new(&model)?;
//! for _ in 0..100 {
//!     step(&model, &mut state, &RobotCommand::Nominal)?;
//! }
//! assert!((state.time_s() - 0.1).abs() < 1e-12);
//! # Ok::<(), workcell_sim::SimError>(())
//! ```

mod cell;
mod clutter;
#[cfg(feature = "mujoco")]
pub mod crosscheck;
pub mod dataset;
mod error;
pub mod human;
pub mod ik;
mod multibody;
mod planning;
pub mod retarget;
pub mod scenario;
mod scene;
pub mod trajectory;

pub use cell::{CellModel, CellState, RobotCommand, step};
pub use clutter::ClutterBox;
pub use error::{Result, SimError};
pub use multibody::{RapierCheck, check_in_rapier};
pub use scenario::Scenario;
pub use scene::CellScene;
/// The renderer crate, which this crate renders its cell with.
pub use workcell_render as render;
