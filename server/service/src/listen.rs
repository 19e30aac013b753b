//! Accepting connections. `axum::serve` has no header timeout, no cap on open connections and
//! no back-off for most `accept` errors, so one client holding a thousand idle sockets locked
//! everyone out; this loop drives hyper's HTTP/1 connections itself (what `axum::serve` does
//! underneath) with all three.

use super::error::ApiError;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::IntoResponse;
use axum::Router;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::net::IpAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{ready, Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Semaphore};

/// How many connections the service holds and how long one may take to ask for something.
#[derive(Clone, Debug)]
pub struct ConnectionLimits {
    pub max_connections: usize,
    /// Per client address (IPv6: per /64, which one client usually has whole).
    pub max_per_address: usize,
    /// A connection must send a whole request head within this of opening or of its previous
    /// response: idle connections and slow headers alike are closed after it.
    pub header_timeout: Duration,
    /// Largest request head the middleware answers with a JSON 431 (see
    /// [`super::http::check_head`]); hyper's parser buffers up to twice as much before it
    /// gives up with a bare 431 of its own.
    pub max_header_bytes: usize,
}

/// Connections over a cap get a short JSON refusal; at most this many are being answered at
/// once, beyond which a refused connection is closed unanswered, so refusing costs little too.
const REFUSALS_AT_ONCE: usize = 64;
/// How long a refused connection has to send its request and take the answer.
const REFUSAL_TIME: Duration = Duration::from_secs(2);
/// Request headers counted against hyper's own limit; the middleware refuses more than
/// [`super::http::MAX_HEADERS`] with a JSON 431 first.
const PARSER_MAX_HEADERS: usize = 4 * super::http::MAX_HEADERS;

/// Serves `app` on `listener` until `shutdown` turns true, then lets requests in flight
/// finish (streams end through their own shutdown path).
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnectionLimits,
    mut shutdown: watch::Receiver<bool>,
) {
    let open = Arc::new(OpenConnections::new(&limits));
    let refusals = Arc::new(Semaphore::new(REFUSALS_AT_ONCE));
    let mut builder = http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout)
        .max_buf_size((2 * (limits.max_header_bytes + super::http::MAX_URI_BYTES)).max(8192))
        .max_headers(PARSER_MAX_HEADERS);
    let builder = Arc::new(builder);
    // Every connection task holds a receiver; all dropped means all finished.
    let (finished_tx, finished_rx) = watch::channel(());
    let mut backoff = Backoff::default();
    loop {
        let (stream, peer) = tokio::select! {
            accepted = accept_with_backoff(|| listener.accept(), &mut backoff) => accepted,
            _ = shutdown.wait_for(|s| *s) => break,
        };
        match open.admit(peer.ip()) {
            Ok(slot) => {
                tokio::spawn(connection(
                    Lingering::new(stream, Some(slot)),
                    app.clone(),
                    Arc::clone(&builder),
                    shutdown.clone(),
                    finished_rx.clone(),
                ));
            }
            Err(refusal) => {
                ::metrics::counter!(super::metrics::CONNECTIONS_REFUSED, "reason" => refusal.body.error.clone())
                    .increment(1);
                if let Ok(permit) = Arc::clone(&refusals).try_acquire_owned() {
                    tokio::spawn(async move {
                        refuse(stream, refusal).await;
                        drop(permit);
                    });
                }
            }
        }
    }
    drop(finished_rx);
    finished_tx.closed().await;
}

async fn connection(
    io: Lingering,
    app: Router,
    builder: Arc<http1::Builder>,
    mut shutdown: watch::Receiver<bool>,
    _finished: watch::Receiver<()>,
) {
    let conn = builder
        .serve_connection(TokioIo::new(io), TowerToHyperService::new(app))
        .with_upgrades();
    tokio::pin!(conn);
    let served = tokio::select! {
        served = conn.as_mut() => Some(served),
        _ = shutdown.wait_for(|s| *s) => None,
    };
    let served = match served {
        Some(served) => served,
        None => {
            conn.as_mut().graceful_shutdown();
            conn.await
        }
    };
    if let Err(e) = served {
        tracing::debug!("connection ended: {e}");
    }
}

/// Answers the connection's first request with `refusal` and closes it.
async fn refuse(stream: TcpStream, refusal: ApiError) {
    let mut builder = http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(REFUSAL_TIME)
        .keep_alive(false);
    let service = hyper::service::service_fn(move |_| {
        let mut response = refusal.clone().into_response();
        response
            .headers_mut()
            .insert(header::CONNECTION, HeaderValue::from_static("close"));
        std::future::ready(Ok::<_, std::convert::Infallible>(response))
    });
    let _ = tokio::time::timeout(
        REFUSAL_TIME,
        builder.serve_connection(TokioIo::new(Lingering::new(stream, None)), service),
    )
    .await;
}

/// Waits between failed accepts: 5 ms doubling to 1 s, from the start again after a success.
/// Out of file descriptors (EMFILE), `accept` fails again at once until a connection closes;
/// retrying at once would only spin a core and flood the log.
#[derive(Debug, Default)]
struct Backoff {
    failures: u32,
}

impl Backoff {
    const FIRST: Duration = Duration::from_millis(5);
    const MOST: Duration = Duration::from_secs(1);

    fn next(&mut self) -> Duration {
        let wait = Self::FIRST.saturating_mul(1 << self.failures.min(16));
        self.failures += 1;
        wait.min(Self::MOST)
    }
}

/// The next accepted connection, retrying failures after [`Backoff`].
async fn accept_with_backoff<T, F, Fut>(mut accept: F, backoff: &mut Backoff) -> T
where
    F: FnMut() -> Fut,
    Fut: Future<Output = io::Result<T>>,
{
    loop {
        match accept().await {
            Ok(accepted) => {
                backoff.failures = 0;
                return accepted;
            }
            Err(e) => {
                let wait = backoff.next();
                tracing::warn!("accept error: {e}; retrying in {} ms", wait.as_millis());
                ::metrics::counter!(super::metrics::ERRORS, "kind" => "accept").increment(1);
                tokio::time::sleep(wait).await;
            }
        }
    }
}

/// Open connections, in total and per client address.
struct OpenConnections {
    max_total: usize,
    max_per_address: usize,
    counts: Mutex<(usize, HashMap<IpAddr, usize>)>,
}

impl OpenConnections {
    fn new(limits: &ConnectionLimits) -> Self {
        Self {
            max_total: limits.max_connections,
            max_per_address: limits.max_per_address,
            counts: Mutex::new((0, HashMap::new())),
        }
    }

    /// A slot for a connection from `ip`, or the refusal to answer it with.
    fn admit(self: &Arc<Self>, ip: IpAddr) -> Result<Slot, ApiError> {
        let address = client_address(ip);
        let mut counts = super::sync::lock(&self.counts);
        let (total, per_address) = &mut *counts;
        if *total >= self.max_total {
            return Err(ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "too_many_connections",
                format!(
                    "the server holds its limit of {} connections; try again shortly",
                    self.max_total
                ),
            ));
        }
        let mine = per_address.entry(address).or_default();
        if *mine >= self.max_per_address {
            return Err(ApiError::too_many(
                "too_many_connections",
                format!(
                    "your address holds this server's limit of {} connections; close some",
                    self.max_per_address
                ),
            ));
        }
        *mine += 1;
        *total += 1;
        ::metrics::gauge!(super::metrics::CONNECTIONS).set(*total as f64);
        Ok(Slot {
            open: Arc::clone(self),
            address,
        })
    }
}

/// What counts as one client: an IPv4 address, or an IPv6 /64 (a host usually has a whole
/// /64 and could otherwise open connections from as many addresses as it likes).
fn client_address(ip: IpAddr) -> IpAddr {
    match ip {
        IpAddr::V4(_) => ip,
        IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
            Some(v4) => IpAddr::V4(v4),
            None => IpAddr::V6((u128::from(v6) & !u128::from(u64::MAX)).into()),
        },
    }
}

/// One open connection's place in [`OpenConnections`], given back when dropped.
struct Slot {
    open: Arc<OpenConnections>,
    address: IpAddr,
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut counts = super::sync::lock(&self.open.counts);
        let (total, per_address) = &mut *counts;
        *total -= 1;
        if let Some(mine) = per_address.get_mut(&self.address) {
            *mine -= 1;
            if *mine == 0 {
                per_address.remove(&self.address);
            }
        }
        ::metrics::gauge!(super::metrics::CONNECTIONS).set(*total as f64);
    }
}

/// Longest a closing connection keeps reading what its client still sends (see [`Lingering`]).
const LINGER_TIME: Duration = Duration::from_secs(2);

/// A socket that closes the way nginx's `lingering_close` does. A response sent before its
/// request body was read (a 413 for a body over its limit, a 400 decided from the query) ends
/// the connection with request bytes still unread, and closing a socket with unread bytes makes
/// the kernel send a reset instead of a FIN; a reset makes the client's kernel discard the
/// response the client has not read yet, so the client saw "connection reset" instead of the
/// JSON error, now and then (issue 15's hardening test, on CI). Shutting down here sends the
/// FIN after the response, then reads and drops what the client still sends until it closes
/// too or [`LINGER_TIME`] passes, and only then lets the socket go.
///
/// It also holds the connection's [`Slot`] (none for a refused one) for as long as it is open,
/// also after hyper hands it over to a WebSocket.
struct Lingering {
    io: TcpStream,
    /// Set once the write side is shut down: when to stop reading.
    deadline: Option<Pin<Box<tokio::time::Sleep>>>,
    _slot: Option<Slot>,
}

impl Lingering {
    fn new(io: TcpStream, slot: Option<Slot>) -> Self {
        Self {
            io,
            deadline: None,
            _slot: slot,
        }
    }
}

impl AsyncRead for Lingering {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

impl AsyncWrite for Lingering {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.io).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.io).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = &mut *self;
        if this.deadline.is_none() {
            ready!(Pin::new(&mut this.io).poll_shutdown(cx))?;
            this.deadline = Some(Box::pin(tokio::time::sleep(LINGER_TIME)));
        }
        let mut scratch = [0u8; 8192];
        loop {
            if let Some(deadline) = this.deadline.as_mut() {
                if deadline.as_mut().poll(cx).is_ready() {
                    return Poll::Ready(Ok(()));
                }
            }
            let mut buf = ReadBuf::new(&mut scratch);
            match ready!(Pin::new(&mut this.io).poll_read(cx, &mut buf)) {
                // More of what the client sent: dropped. Reads are under tokio's cooperative
                // budget, so a fast sender cannot hold this task's thread.
                Ok(()) if !buf.filled().is_empty() => {}
                // The client closed (or reset) its side: nothing can be lost any more.
                Ok(()) | Err(_) => return Poll::Ready(Ok(())),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fifty failed accepts in a row (as when the process is out of file descriptors) are
    /// retried with growing pauses, not at once: virtual time (the test pauses the clock) must
    /// pass between them, and none waits longer than the cap.
    #[tokio::test(start_paused = true)]
    async fn failing_accepts_back_off_up_to_a_second() {
        let started = tokio::time::Instant::now();
        let mut calls = 0u32;
        let mut backoff = Backoff::default();
        let accepted = accept_with_backoff(
            || {
                calls += 1;
                let result = if calls <= 50 {
                    Err(io::Error::from_raw_os_error(24))
                } else {
                    Ok(calls)
                };
                std::future::ready(result)
            },
            &mut backoff,
        )
        .await;
        assert_eq!(accepted, 51);
        let waited = started.elapsed();
        // 5, 10, … 640 ms (1.275 s), then 1 s for each of the other 42 failures.
        assert_eq!(waited, Duration::from_millis(1275 + 42_000));
        assert_eq!(backoff.failures, 0, "a success starts the back-off again");
    }

    #[test]
    fn clients_are_addresses_or_ipv6_slash_64s() {
        let a: IpAddr = "2001:db8::1".parse().expect("address");
        let b: IpAddr = "2001:db8::ffff:2".parse().expect("address");
        let other: IpAddr = "2001:db8:0:1::1".parse().expect("address");
        assert_eq!(client_address(a), client_address(b));
        assert_ne!(client_address(a), client_address(other));
        let mapped: IpAddr = "::ffff:10.0.0.1".parse().expect("address");
        assert_eq!(
            client_address(mapped),
            "10.0.0.1".parse::<IpAddr>().expect("v4")
        );
    }

    #[test]
    fn connections_are_capped_per_address_and_in_total() {
        let open = Arc::new(OpenConnections::new(&ConnectionLimits {
            max_connections: 3,
            max_per_address: 2,
            header_timeout: Duration::from_secs(1),
            max_header_bytes: 1024,
        }));
        let a: IpAddr = "10.0.0.1".parse().expect("address");
        let b: IpAddr = "10.0.0.2".parse().expect("address");
        let first = open.admit(a).expect("first");
        let _second = open.admit(a).expect("second");
        let third = open
            .admit(a)
            .err()
            .expect("a third from one address is refused");
        assert_eq!(third.status, StatusCode::TOO_MANY_REQUESTS);
        let _other = open.admit(b).expect("another address");
        let full = open.admit(b).err().expect("the total is reached");
        assert_eq!(full.status, StatusCode::SERVICE_UNAVAILABLE);
        drop(first);
        open.admit(a).expect("a closed connection frees its slot");
    }
}
