//! Sessions across replicas (issue 14, part 3): a session lives on the replica that renders
//! it, so its id says which one. With `--replica NAME` and a routing key shared by every
//! replica, session ids are `NAME.se_<random>.<mac>`, the mac an HMAC-SHA256 over the rest
//! under the key. A proxy routes `/v1/sessions/NAME.…` to the replica called NAME (the part
//! before the first dot; replica names are DNS labels, so they hold none); any replica can
//! check an id it is given and, if the id is genuine but another replica's, answer 421
//! naming the owner instead of 404. Nothing is shared between replicas but the key.

use hmac::{Hmac, Mac};
use sha2::Sha256;

/// Hex digits of the mac in an id (128 bits).
const MAC_HEX: usize = 32;
/// Fewest bytes of routing key.
pub const MIN_KEY_BYTES: usize = 32;

/// Why routing cannot be set up.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RoutingError {
    #[error("replica name '{0}' must be 1 to 63 lowercase letters, digits or '-', not starting or ending with '-' (a DNS label, e.g. a StatefulSet pod name)")]
    Name(String),
    #[error("the routing key has {0} bytes; use at least {MIN_KEY_BYTES} random bytes")]
    ShortKey(usize),
    #[error("the routing key's bytes repeat too much to be random (about {0} bits by their frequencies, at least {MIN_KEY_BITS} needed); use at least {MIN_KEY_BYTES} random bytes, e.g. `head -c 32 /dev/urandom | base64`")]
    WeakKey(u32),
}

/// Fewest bits a routing key's byte frequencies must carry: the strength of the mac.
pub const MIN_KEY_BITS: u32 = 128;

/// The bits a key's byte frequencies carry (its length times the Shannon entropy of its byte
/// histogram): an upper bound on its real entropy that catches keys a person typed, spaces or
/// a word repeated, while random bytes, hex or base64 of 32 random bytes pass.
fn frequency_bits(key: &[u8]) -> f64 {
    let mut counts = [0u32; 256];
    for &b in key {
        counts[usize::from(b)] += 1;
    }
    let n = key.len() as f64;
    counts
        .iter()
        .filter(|&&c| c > 0)
        .map(|&c| -f64::from(c) * (f64::from(c) / n).log2())
        .sum()
}

/// Whose session an id names.
#[derive(Debug, PartialEq, Eq)]
pub enum Owner {
    /// This replica's (or an id without a replica, when routing is off).
    Here,
    /// A genuine id of the replica so named.
    Elsewhere(String),
    /// An id with a replica part whose mac does not check: made up or altered.
    Forged,
}

/// This replica's name and the key every replica shares.
#[derive(Clone)]
pub struct Routing {
    replica: String,
    key: Vec<u8>,
}

impl std::fmt::Debug for Routing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Routing")
            .field("replica", &self.replica)
            .finish_non_exhaustive()
    }
}

/// Whether `name` is a DNS label of lowercase letters, digits and '-'.
fn valid_name(name: &str) -> bool {
    (1..=63).contains(&name.len())
        && !name.starts_with('-')
        && !name.ends_with('-')
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-')
}

impl Routing {
    pub fn new(replica: &str, key: &[u8]) -> Result<Self, RoutingError> {
        if !valid_name(replica) {
            return Err(RoutingError::Name(crate::service::error::echo(replica)));
        }
        if key.len() < MIN_KEY_BYTES {
            return Err(RoutingError::ShortKey(key.len()));
        }
        let bits = frequency_bits(key);
        if bits < f64::from(MIN_KEY_BITS) {
            return Err(RoutingError::WeakKey(bits as u32));
        }
        Ok(Self {
            replica: replica.to_string(),
            key: key.to_vec(),
        })
    }

    pub fn replica(&self) -> &str {
        &self.replica
    }

    fn mac(&self, message: &str) -> String {
        // HMAC takes keys of any length; `new_from_slice` cannot fail for it.
        let Ok(mut mac) = Hmac::<Sha256>::new_from_slice(&self.key) else {
            unreachable!("HMAC accepts every key length")
        };
        mac.update(message.as_bytes());
        let bytes = mac.finalize().into_bytes();
        bytes
            .iter()
            .take(MAC_HEX / 2)
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    /// A new session id of this replica: `NAME.se_<random>.<mac>`.
    pub fn session_id(&self) -> String {
        let body = format!("{}.{}", self.replica, super::ids::new_id("se"));
        let mac = self.mac(&body);
        format!("{body}.{mac}")
    }

    /// Whose session `id` is. Ids without a replica part are this replica's to look up (and
    /// to not find).
    pub fn owner(&self, id: &str) -> Owner {
        let Some((body, mac)) = id.rsplit_once('.') else {
            return Owner::Here;
        };
        let Some((replica, _)) = body.split_once('.') else {
            return Owner::Forged;
        };
        if mac.len() != MAC_HEX || !super::ids::constant_time_eq(mac, &self.mac(body)) {
            return Owner::Forged;
        }
        if replica == self.replica {
            Owner::Here
        } else {
            Owner::Elsewhere(replica.to_string())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const KEY: &[u8] = b"0123456789abcdef0123456789abcdef";

    #[test]
    fn ids_name_their_replica_and_check_on_every_replica_with_the_key() {
        let a = Routing::new("lightcast-0", KEY).expect("a");
        let b = Routing::new("lightcast-1", KEY).expect("b");
        let id = a.session_id();
        assert!(id.starts_with("lightcast-0.se_"), "{id}");
        assert_eq!(id.split('.').count(), 3, "{id}");
        assert_eq!(a.owner(&id), Owner::Here);
        assert_eq!(b.owner(&id), Owner::Elsewhere("lightcast-0".into()));
        assert_ne!(a.session_id(), id, "ids are random");
    }

    #[test]
    fn altered_or_foreign_ids_are_forged() {
        let a = Routing::new("lightcast-0", KEY).expect("a");
        let id = a.session_id();
        // Another owner with the same mac, a flipped mac digit, a truncated mac.
        let moved = id.replacen("lightcast-0", "lightcast-2", 1);
        assert_eq!(a.owner(&moved), Owner::Forged);
        let mut flipped = id.clone();
        let last = flipped.pop().expect("a digit");
        flipped.push(if last == '0' { '1' } else { '0' });
        assert_eq!(a.owner(&flipped), Owner::Forged);
        assert_eq!(a.owner(&id[..id.len() - 1]), Owner::Forged);
        assert_eq!(a.owner("lightcast-0.x"), Owner::Forged);
        // The same id under another key.
        let other = Routing::new("lightcast-1", b"fedcba9876543210FEDCBA9876543210").expect("c");
        assert_eq!(other.owner(&id), Owner::Forged);
        // Plain ids (routing was off when they were made) are looked up here.
        assert_eq!(a.owner("se_0123456789abcdef"), Owner::Here);
    }

    #[test]
    fn names_are_dns_labels_and_keys_are_long() {
        for bad in ["", "-a", "a-", "A", "a.b", "a_b", &"x".repeat(64)] {
            assert!(
                matches!(Routing::new(bad, KEY), Err(RoutingError::Name(_))),
                "{bad:?}"
            );
        }
        assert!(Routing::new("lightcast-12", KEY).is_ok());
        assert_eq!(
            Routing::new("a", b"short").err(),
            Some(RoutingError::ShortKey(5))
        );
        // Long enough, but nobody's random bytes (issue 30: 40 spaces were taken).
        for weak in [
            &[b' '; 40][..],
            b"passwordpasswordpasswordpassword",
            &[b'a'; 64][..],
        ] {
            assert!(
                matches!(Routing::new("a", weak), Err(RoutingError::WeakKey(_))),
                "{weak:?}"
            );
        }
        // What operators are told to use passes: random bytes, as hex or base64.
        let random: Vec<u8> = (0u32..32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
            .collect();
        let hex: String = random.iter().map(|b| format!("{b:02x}")).collect();
        for good in [
            &random[..],
            hex.as_bytes(),
            b"q3V8mZkq1Xb0cJp4T9rLw2YhN6sDfGa7Ue5iOxBtRvM=",
        ] {
            assert!(
                Routing::new("a", good).is_ok(),
                "{good:?}: {} bits",
                frequency_bits(good)
            );
        }
    }
}
