//! Budgets of what clients can make the server hold: memory (decoded texture bytes,
//! triangles, the GI methods' precomputations in the pools they declare) over every scene, and per-token quotas (sessions, scenes, uploads
//! in flight, queued one-shot renders). Each is a [`Pool`] taken from *before* the memory or
//! slot is used and given back when the holder is dropped, so a refusal never comes after the
//! allocation it guards and nothing leaks when a request ends early.

use super::error::ApiError;
use super::sync::lock;
use crate::gi::limits::GiLimit;
use axum::http::StatusCode;
use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// A limited amount (bytes, triangles, caches, slots) shared by its holders.
#[derive(Debug)]
pub struct Pool {
    limit: u64,
    used: AtomicU64,
}

impl Pool {
    pub fn new(limit: u64) -> Arc<Self> {
        Arc::new(Self {
            limit,
            used: AtomicU64::new(0),
        })
    }

    pub fn limit(&self) -> u64 {
        self.limit
    }

    pub fn used(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }

    /// What is left now (another holder may take it before the caller does).
    pub fn available(&self) -> u64 {
        self.limit.saturating_sub(self.used())
    }

    /// Takes `amount` if that much is left; `None` leaves the pool unchanged.
    pub fn try_take(self: &Arc<Self>, amount: u64) -> Option<Held> {
        self.add(amount).then(|| Held {
            pool: Arc::clone(self),
            amount,
        })
    }

    fn add(&self, amount: u64) -> bool {
        self.used
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |used| {
                used.checked_add(amount)
                    .filter(|&total| total <= self.limit)
            })
            .is_ok()
    }
}

/// An amount taken from a [`Pool`], given back on drop.
#[derive(Debug)]
pub struct Held {
    pool: Arc<Pool>,
    amount: u64,
}

impl Held {
    pub fn amount(&self) -> u64 {
        self.amount
    }

    /// Holds exactly `amount` from now on (an estimate turned out too large or too small):
    /// gives back the surplus, or takes the shortfall if the pool has it. False when it does
    /// not; nothing changes then.
    pub fn resize(&mut self, amount: u64) -> bool {
        if amount <= self.amount {
            self.pool
                .used
                .fetch_sub(self.amount - amount, Ordering::AcqRel);
        } else if !self.pool.add(amount - self.amount) {
            return false;
        }
        self.amount = amount;
        true
    }
}

impl Drop for Held {
    fn drop(&mut self) {
        self.pool.used.fetch_sub(self.amount, Ordering::AcqRel);
    }
}

/// The server-wide memory budgets over every scene held (one-shot uploads included while
/// their request runs).
#[derive(Debug)]
pub struct MemoryBudget {
    /// Decoded texture bytes (RGBA8, after downscaling).
    pub texture_bytes: Arc<Pool>,
    pub triangles: Arc<Pool>,
    /// The pools the GI methods declare for their precomputations, by the name of the limit
    /// that sizes them (`max_total_caches`; see `gi::precompute::BudgetPool`).
    gi: BTreeMap<&'static str, Arc<Pool>>,
    limits: lightcast_protocol::Limits,
}

impl MemoryBudget {
    pub fn new(limits: &lightcast_protocol::Limits) -> Self {
        // One pool per total a registered precomputation is counted against.
        let gi = crate::gi::REGISTRY
            .iter()
            .filter_map(|e| e.precompute?.budget.as_ref())
            .filter_map(|b| match b.pool {
                crate::gi::precompute::BudgetPool::Declared { total, .. } => Some(total),
                crate::gi::precompute::BudgetPool::Triangles => None,
            })
            .map(|l| (l.name, Pool::new(l.of(limits))))
            .collect();
        Self {
            texture_bytes: Pool::new(limits.max_total_texture_bytes),
            triangles: Pool::new(limits.max_total_triangles),
            gi,
            limits: limits.clone(),
        }
    }

    /// The pool a GI method's limit `total` sizes (every total a registered precomputation
    /// declares has one).
    pub fn gi_pool(&self, total: &GiLimit) -> Option<&Arc<Pool>> {
        self.gi.get(total.name)
    }

    /// The value of a GI method's limit on this server (a per-set cap).
    pub fn gi_limit(&self, limit: &GiLimit) -> u64 {
        limit.of(&self.limits)
    }
}

/// What one token may hold at once.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Quota {
    Sessions,
    Scenes,
    Uploads,
    Renders,
}

impl Quota {
    /// The error kind and the flag that sets it.
    fn names(self) -> (&'static str, &'static str) {
        match self {
            Quota::Sessions => ("session_quota", "--token-max-sessions"),
            Quota::Scenes => ("scene_quota", "--token-max-scenes"),
            Quota::Uploads => ("upload_quota", "--token-max-uploads"),
            Quota::Renders => ("render_quota", "--token-max-renders"),
        }
    }

    fn what(self) -> &'static str {
        match self {
            Quota::Sessions => "sessions",
            Quota::Scenes => "scenes",
            Quota::Uploads => "scene uploads in flight",
            Quota::Renders => "one-shot renders queued or running",
        }
    }
}

/// Per-token quotas: with auth on, one token cannot take every slot of the server's global
/// limits. Without auth every client is the same anonymous caller and only the global limits
/// apply.
#[derive(Debug)]
pub struct TokenQuotas {
    limits: HashMap<Quota, u32>,
    pools: Mutex<HashMap<(String, Quota), Arc<Pool>>>,
}

impl TokenQuotas {
    pub fn new(limits: &lightcast_protocol::Limits) -> Self {
        let pairs = [
            (Quota::Sessions, limits.token_max_sessions),
            (Quota::Scenes, limits.token_max_scenes),
            (Quota::Uploads, limits.token_max_uploads),
            (Quota::Renders, limits.token_max_renders),
        ];
        Self {
            limits: pairs
                .into_iter()
                .filter_map(|(q, limit)| Some((q, limit?)))
                .collect(),
            pools: Mutex::new(HashMap::new()),
        }
    }

    /// The quota of `kind` for `token`, or `None` when no quota applies (auth off).
    pub fn limit(&self, token: Option<&str>, kind: Quota) -> Option<u32> {
        token.and(self.limits.get(&kind).copied())
    }

    /// 429 `<kind>_quota` naming the quota and its flag.
    pub fn refusal(&self, kind: Quota, limit: u32) -> ApiError {
        let (error, flag) = kind.names();
        ApiError::too_many(
            error,
            format!(
                "this token holds {limit} {}, its quota ({flag}); wait for one to end",
                kind.what()
            ),
        )
    }

    /// Checks that `held` (what `token` holds now) leaves room for one more of `kind`.
    pub fn check_count(
        &self,
        token: Option<&str>,
        kind: Quota,
        held: usize,
    ) -> Result<(), ApiError> {
        match self.limit(token, kind) {
            Some(limit) if held >= limit as usize => Err(self.refusal(kind, limit)),
            _ => Ok(()),
        }
    }

    /// Takes one slot of `kind` for `token` until the returned holder is dropped.
    pub fn take(&self, token: Option<&str>, kind: Quota) -> Result<Option<Held>, ApiError> {
        let (Some(token), Some(limit)) = (token, self.limit(token, kind)) else {
            return Ok(None);
        };
        let pool = {
            // The token was authenticated already: looking it up in a map reveals nothing.
            let mut pools = lock(&self.pools);
            Arc::clone(
                pools
                    .entry((token.to_string(), kind))
                    .or_insert_with(|| Pool::new(limit.into())),
            )
        };
        pool.try_take(1)
            .map(Some)
            .ok_or_else(|| self.refusal(kind, limit))
    }
}

/// Admission of work that holds memory while it runs: scene uploads (their bodies) and
/// one-shot renders (their frames), each within a server-wide limit and the caller's quota.
#[derive(Debug)]
pub struct Admission {
    quotas: TokenQuotas,
    uploads: Arc<Pool>,
    renders: Arc<Pool>,
}

/// A place taken by [`Admission`], given back on drop (also when the request is cancelled).
#[derive(Debug)]
pub struct Admitted {
    _global: Held,
    _token: Option<Held>,
}

impl Admission {
    pub fn new(limits: &lightcast_protocol::Limits) -> Self {
        Self {
            quotas: TokenQuotas::new(limits),
            uploads: Pool::new(limits.max_uploads.into()),
            renders: Pool::new(limits.max_queued_renders.into()),
        }
    }

    /// A place for a scene upload of `token`, taken before its body is read.
    pub fn upload(&self, token: Option<&str>) -> Result<Admitted, ApiError> {
        self.admit(
            token,
            Quota::Uploads,
            &self.uploads,
            "too_many_uploads",
            "--max-uploads",
        )
    }

    /// A place for a one-shot render of `token`, from before its request is read until its
    /// answer is made.
    pub fn render(&self, token: Option<&str>) -> Result<Admitted, ApiError> {
        self.admit(
            token,
            Quota::Renders,
            &self.renders,
            "too_many_renders",
            "--max-queued-renders",
        )
    }

    fn admit(
        &self,
        token: Option<&str>,
        kind: Quota,
        global: &Arc<Pool>,
        error: &str,
        flag: &str,
    ) -> Result<Admitted, ApiError> {
        let token_held = self.quotas.take(token, kind)?;
        let global_held = global.try_take(1).ok_or_else(|| {
            ApiError::too_many(
                error,
                format!(
                    "the server has {} {} at once, its limit ({flag}); try again shortly",
                    global.limit(),
                    kind.what()
                ),
            )
        })?;
        Ok(Admitted {
            _global: global_held,
            _token: token_held,
        })
    }
}

/// The fair share of `global` for one of `tokens` tokens (at least one).
pub fn fair_share(global: u32, tokens: usize) -> u32 {
    let tokens = u32::try_from(tokens.max(1)).unwrap_or(u32::MAX);
    global.div_ceil(tokens).max(1)
}

/// 413 `<kind>` naming the budget and its flag, for an upload the server cannot hold.
pub fn over_budget(kind: &str, message: impl Into<String>) -> ApiError {
    ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, kind, message)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::error::RETRY_AFTER_SECS;

    #[test]
    fn a_pool_refuses_beyond_its_limit_and_gets_back_what_holders_drop() {
        let pool = Pool::new(10);
        let a = pool.try_take(6).expect("fits");
        assert!(pool.try_take(5).is_none(), "6 + 5 > 10");
        assert_eq!(pool.used(), 6, "a refusal takes nothing");
        let mut b = pool.try_take(4).expect("6 + 4 = 10 fits");
        assert_eq!(pool.available(), 0);
        assert!(b.resize(1));
        assert_eq!(pool.available(), 3);
        assert!(!b.resize(5), "1 + 3 left < 5");
        assert_eq!((b.amount(), pool.used()), (1, 7));
        assert!(b.resize(4));
        assert_eq!(pool.available(), 0);
        assert!(b.resize(1));
        drop(a);
        assert_eq!(pool.used(), 1);
        drop(b);
        assert_eq!(pool.used(), 0);
        assert!(pool.try_take(u64::MAX).is_none(), "no overflow");
    }

    fn limits(sessions: Option<u32>, uploads: Option<u32>) -> lightcast_protocol::Limits {
        let mut limits = crate::service::config::tests::default_limits();
        limits.token_max_sessions = sessions;
        limits.token_max_uploads = uploads;
        limits
    }

    #[test]
    fn token_quotas_are_per_token_and_name_the_quota() {
        let quotas = TokenQuotas::new(&limits(Some(2), Some(1)));
        let first = quotas.take(Some("alice"), Quota::Uploads).expect("one");
        let refused = quotas
            .take(Some("alice"), Quota::Uploads)
            .expect_err("alice's quota is one upload");
        assert_eq!(refused.status, StatusCode::TOO_MANY_REQUESTS);
        assert_eq!(refused.body.error, "upload_quota");
        assert_eq!(refused.retry_after, Some(RETRY_AFTER_SECS), "quotas too");
        assert!(refused.body.message.contains("--token-max-uploads"));
        assert!(
            quotas.take(Some("bob"), Quota::Uploads).is_ok(),
            "bob has his own"
        );
        drop(first);
        assert!(quotas.take(Some("alice"), Quota::Uploads).is_ok());
        assert!(quotas
            .check_count(Some("alice"), Quota::Sessions, 1)
            .is_ok());
        let e = quotas
            .check_count(Some("alice"), Quota::Sessions, 2)
            .expect_err("two sessions held");
        assert_eq!(e.body.error, "session_quota");
        assert!(
            quotas
                .take(None, Quota::Uploads)
                .expect("auth off")
                .is_none(),
            "without a token no quota applies"
        );
        let unlimited = TokenQuotas::new(&limits(None, None));
        assert!(unlimited
            .check_count(Some("alice"), Quota::Sessions, 1000)
            .is_ok());
    }

    #[test]
    fn admission_is_limited_globally_and_per_token() {
        let mut l = limits(None, Some(1));
        l.max_uploads = 2;
        let admission = Admission::new(&l);
        let a = admission.upload(Some("alice")).expect("first");
        let e = admission.upload(Some("alice")).expect_err("alice's quota");
        assert_eq!(e.body.error, "upload_quota");
        let b = admission.upload(Some("bob")).expect("bob's first");
        let e = admission
            .upload(Some("carol"))
            .expect_err("the server's limit");
        assert_eq!(
            (e.status, e.body.error.as_str()),
            (StatusCode::TOO_MANY_REQUESTS, "too_many_uploads")
        );
        assert_eq!(e.retry_after, Some(RETRY_AFTER_SECS), "queues too");
        assert!(
            e.body.message.contains("--max-uploads"),
            "{}",
            e.body.message
        );
        drop((a, b));
        assert!(admission.upload(Some("carol")).is_ok());
        assert!(
            admission.render(None).is_ok(),
            "renders have their own limit"
        );
    }

    #[test]
    fn the_fair_share_rounds_up_and_is_never_zero() {
        assert_eq!(fair_share(64, 1), 64);
        assert_eq!(fair_share(64, 3), 22);
        assert_eq!(fair_share(2, 5), 1);
        assert_eq!(fair_share(0, 0), 1);
    }
}
