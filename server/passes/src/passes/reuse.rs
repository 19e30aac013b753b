//! Reusing a pass's output while its inputs stay the same (issue 36). Sessions of one scene
//! take turns on one renderer, and a pass whose inputs do not depend on the camera (a shadow
//! map or an RSM fitted to the scene, under the same lights and poses) need not run again
//! for the next session's frame: its target still holds what those inputs make. A target
//! remembers the inputs it was last made from byte for byte (not a hash: a collision would
//! show a stale image without a trace), and a frame that brings the same bytes reuses it.

use crate::scene::nodes::Poses;
use std::sync::Mutex;

/// What a target was last made from (nothing known: `None`).
#[derive(Debug, Default)]
pub struct MadeFrom(Mutex<Option<Vec<u8>>>);

impl MadeFrom {
    /// Whether the target holds what `inputs` make, so nothing needs encoding; if not, it is
    /// taken to hold them from now on (the caller encodes the pass, or [`Self::forget`]s on
    /// failure). `None` (reuse off): never, and nothing is remembered.
    pub fn holds(&self, inputs: Option<&[u8]>) -> bool {
        let mut made = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match inputs {
            Some(inputs) if made.as_deref() == Some(inputs) => true,
            Some(inputs) => {
                *made = Some(inputs.to_vec());
                false
            }
            None => {
                *made = None;
                false
            }
        }
    }

    /// The target's content is unknown (a pass that was to make it failed).
    pub fn forget(&self) {
        *self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
    }
}

/// The bytes of `poses` (what a frame's vertex buffer holds besides the scene at rest).
pub fn pose_bytes(poses: &Poses) -> Vec<u8> {
    let mut out = Vec::with_capacity(poses.len() * 44);
    for (id, t) in poses {
        out.extend_from_slice(&id.to_le_bytes());
        for v in t
            .translation
            .to_array()
            .into_iter()
            .chain(t.rotation.to_array())
            .chain(t.scale.to_array())
        {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_target_is_reused_only_for_the_very_inputs_it_was_made_from() {
        let made = MadeFrom::default();
        assert!(!made.holds(Some(b"a")), "nothing made yet");
        assert!(made.holds(Some(b"a")));
        assert!(!made.holds(Some(b"b")), "other inputs");
        assert!(made.holds(Some(b"b")));
        assert!(!made.holds(None), "reuse off");
        assert!(!made.holds(Some(b"b")), "reuse off forgot what it held");
        made.forget();
        assert!(!made.holds(Some(b"b")), "forgotten");
    }
}
