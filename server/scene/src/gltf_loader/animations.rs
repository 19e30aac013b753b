//! Animations (glTF 2.0 §3.11): every channel's keys read and checked, for the nodes they
//! move; and which nodes may move at all.

use super::*;
use crate::nodes::{Animation, Channel, Interpolation, Property};

/// Most key values (times and components, 16 M: 64 MB decoded) a file's animations may hold.
const MAX_ANIMATION_VALUES: u64 = 1 << 24;

/// Whether a node's `extras` mark it movable (`{"movable": true}`): a static file's part a
/// client may drag.
pub(super) fn marked_movable(extras: &json::Extras) -> bool {
    extras
        .as_ref()
        .and_then(|raw| serde_json::from_str::<serde_json::Value>(raw.get()).ok())
        .and_then(|v| v.get("movable").and_then(serde_json::Value::as_bool))
        .unwrap_or(false)
}

impl Loader<'_> {
    /// The file's animations, their keys checked: times finite, non-negative and increasing,
    /// values finite and as many as the times ask for.
    pub(super) fn animations(&self) -> Result<Vec<Animation>, LoadError> {
        let mut out = Vec::with_capacity(self.root.animations.len());
        // Channels may share one large accessor: the decoded keys are counted before reading.
        let mut values = 0u64;
        for (index, animation) in self.root.animations.iter().enumerate() {
            let part = named("animation", index, animation.name.as_deref());
            let mut channels = Vec::with_capacity(animation.channels.len());
            for (c, channel) in animation.channels.iter().enumerate() {
                let part = format!("{part} channel {c}");
                values = values.saturating_add(self.channel_values(animation, channel));
                if values > MAX_ANIMATION_VALUES {
                    return Err(invalid(
                        part,
                        format!(
                            "the file's animations would hold more than {MAX_ANIMATION_VALUES} \
                             key values"
                        ),
                    ));
                }
                channels.push(self.channel(animation, channel, &part)?);
            }
            out.push(Animation {
                name: animation
                    .name
                    .clone()
                    .filter(|n| !n.is_empty())
                    .unwrap_or_else(|| format!("animation {index}")),
                channels,
            });
        }
        Ok(out)
    }

    /// An upper bound on the components a channel's input and output accessors decode to
    /// (their element counts, four components each at most).
    fn channel_values(
        &self,
        animation: &json::Animation,
        channel: &json::animation::Channel,
    ) -> u64 {
        let count = |accessor: usize| {
            self.root
                .accessors
                .get(accessor)
                .map_or(0, |a| a.count.0 * 4)
        };
        animation
            .samplers
            .get(channel.sampler.value())
            .map_or(0, |s| count(s.input.value()) + count(s.output.value()))
    }

    fn channel(
        &self,
        animation: &json::Animation,
        channel: &json::animation::Channel,
        part: &str,
    ) -> Result<Channel, LoadError> {
        let sampler_index = channel.sampler.value();
        let sampler = animation
            .samplers
            .get(sampler_index)
            .ok_or_else(|| invalid(part, format!("sampler {sampler_index} does not exist")))?;
        let Checked::Valid(path) = channel.target.path else {
            return Err(invalid(part, "target path is not one glTF defines"));
        };
        let Checked::Valid(interpolation) = sampler.interpolation else {
            return Err(invalid(part, "interpolation is not one glTF defines"));
        };
        let (property, ty) = match path {
            json::animation::Property::Translation => (Property::Translation, Type::Vec3),
            json::animation::Property::Rotation => (Property::Rotation, Type::Vec4),
            json::animation::Property::Scale => (Property::Scale, Type::Vec3),
            json::animation::Property::MorphTargetWeights => (Property::Weights, Type::Scalar),
        };
        let interpolation = match interpolation {
            json::animation::Interpolation::Linear => Interpolation::Linear,
            json::animation::Interpolation::Step => Interpolation::Step,
            json::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
        };
        let times = self.read_floats(sampler.input.value(), Type::Scalar, part, "input")?;
        if times.is_empty() {
            return Err(invalid(part, "input has no keys"));
        }
        if let Some(i) = times.iter().position(|t| !t.is_finite() || *t < 0.0) {
            return Err(invalid(
                part,
                format!("input key {i} is {} (times are finite and ≥ 0)", times[i]),
            ));
        }
        if let Some(i) = times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(invalid(
                part,
                format!("input key {} does not come after key {i}", i + 1),
            ));
        }
        let values = self.read_floats(sampler.output.value(), ty, part, "output")?;
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(invalid(part, format!("output component {i} is not finite")));
        }
        let per_key = match interpolation {
            Interpolation::CubicSpline => 3,
            _ => 1,
        } * match ty {
            Type::Vec4 => 4,
            Type::Vec3 => 3,
            _ => 1,
        };
        let keys = times.len() * per_key;
        // Morph weights hold one value per target and key.
        let (fits, each) = match property {
            Property::Weights => (
                !values.is_empty() && values.len().is_multiple_of(keys),
                " or a multiple",
            ),
            _ => (values.len() == keys, ""),
        };
        if !fits {
            return Err(invalid(
                part,
                format!(
                    "output holds {} components for {} keys ({per_key}{each} per key)",
                    values.len(),
                    times.len()
                ),
            ));
        }
        Ok(Channel {
            node: channel.target.node.value() as u32,
            property,
            interpolation,
            times,
            values,
        })
    }
}
