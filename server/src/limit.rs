//! The request-size limit, `server.max_request_bytes`, enforced on the wire: [`RequestLimit`]
//! wraps a gRPC service and reads the length prefix of every message of each request body as it
//! streams in. A message announced larger than the limit fails the body with
//! [`Error::RequestTooLarge`] (RESOURCE_EXHAUSTED, through `status.rs`), before its bytes are
//! buffered, and the messages before it are delivered first.
//!
//! Tonic enforces the same limit itself, but answers OUT_OF_RANGE ("decoded message length too
//! large") with no word of the setting; gRPC's convention for a message over the limit is
//! RESOURCE_EXHAUSTED. Tonic's check stays as the backstop: this one runs first, on the same
//! bytes.

use std::pin::Pin;
use std::task::{Context, Poll, ready};

use http_body::{Frame, SizeHint};
use tonic::body::Body;
use tonic::codegen::{Bytes, Service, http};
use tonic::server::NamedService;

use crate::Error;
use crate::status::to_status;

/// A gRPC service whose request messages may be at most `limit` bytes each.
#[derive(Debug, Clone)]
pub(crate) struct RequestLimit<S> {
    inner: S,
    limit: u64,
}

impl<S> RequestLimit<S> {
    /// `inner` with messages of more than `limit` bytes refused.
    pub(crate) fn new(inner: S, limit: u64) -> Self {
        Self { inner, limit }
    }
}

impl<S> Service<http::Request<Body>> for RequestLimit<S>
where
    S: Service<http::Request<Body>>,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future = S::Future;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<Body>) -> Self::Future {
        let limit = self.limit;
        self.inner
            .call(request.map(|body| Body::new(LimitedBody::new(body, limit))))
    }
}

impl<S: NamedService> NamedService for RequestLimit<S> {
    const NAME: &'static str = S::NAME;
}

/// A request body that fails when a gRPC message in it is announced larger than `limit`.
struct LimitedBody {
    inner: Body,
    framing: Framing,
    limit: u64,
    /// The refusal, held back while the bytes before the oversized message are delivered.
    refused: Option<tonic::Status>,
    done: bool,
}

impl LimitedBody {
    fn new(inner: Body, limit: u64) -> Self {
        Self {
            inner,
            framing: Framing::default(),
            limit,
            refused: None,
            done: false,
        }
    }
}

impl http_body::Body for LimitedBody {
    type Data = Bytes;
    type Error = tonic::Status;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, tonic::Status>>> {
        let this = self.get_mut();
        if let Some(status) = this.refused.take() {
            this.done = true;
            return Poll::Ready(Some(Err(status)));
        }
        if this.done {
            return Poll::Ready(None);
        }
        let frame = match ready!(Pin::new(&mut this.inner).poll_frame(cx)) {
            Some(Ok(frame)) => frame,
            other => return Poll::Ready(other),
        };
        let mut data = match frame.into_data() {
            Ok(data) => data,
            // Trailers carry no messages.
            Err(frame) => return Poll::Ready(Some(Ok(frame))),
        };
        let Some(Oversized { start, bytes }) = this.framing.scan(&data, this.limit) else {
            return Poll::Ready(Some(Ok(Frame::data(data))));
        };
        let status = to_status(&Error::RequestTooLarge {
            bytes,
            limit: this.limit,
        });
        if start == 0 {
            this.done = true;
            return Poll::Ready(Some(Err(status)));
        }
        data.truncate(start);
        this.refused = Some(status);
        Poll::Ready(Some(Ok(Frame::data(data))))
    }

    fn is_end_stream(&self) -> bool {
        self.refused.is_none() && (self.done || self.inner.is_end_stream())
    }

    fn size_hint(&self) -> SizeHint {
        // The body may end early, so only the upper bound of the inner body still holds.
        let mut hint = SizeHint::new();
        if let Some(upper) = self.inner.size_hint().upper() {
            hint.set_upper(upper);
        }
        hint
    }
}

/// A message whose length prefix announces more than the limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Oversized {
    /// Where its prefix starts in the chunk scanned (0 when it started in an earlier chunk).
    start: usize,
    /// The length it announced.
    bytes: u64,
}

/// Where a body is in gRPC's message framing: each message is a 5-byte prefix (a compression
/// flag and a big-endian `u32` length) followed by that many bytes.
#[derive(Debug, Default)]
struct Framing {
    prefix: [u8; 5],
    /// Bytes of the current prefix seen so far (0 = between messages, or inside one).
    prefix_len: usize,
    /// Bytes of the current message still to come.
    remaining: u64,
}

impl Framing {
    /// Follows the framing through the next `chunk` of the body; stops at the first prefix that
    /// announces more than `limit` bytes.
    fn scan(&mut self, chunk: &[u8], limit: u64) -> Option<Oversized> {
        let mut at = 0;
        let mut start = 0;
        while at < chunk.len() {
            if self.remaining > 0 {
                let left = (chunk.len() - at) as u64;
                let skip = self.remaining.min(left);
                self.remaining -= skip;
                at += skip as usize;
                continue;
            }
            if self.prefix_len == 0 {
                start = at;
            }
            self.prefix[self.prefix_len] = chunk[at];
            self.prefix_len += 1;
            at += 1;
            if self.prefix_len == self.prefix.len() {
                self.prefix_len = 0;
                let [_, a, b, c, d] = self.prefix;
                let bytes = u64::from(u32::from_be_bytes([a, b, c, d]));
                if bytes > limit {
                    return Some(Oversized { start, bytes });
                }
                self.remaining = bytes;
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A gRPC message of `len` payload bytes, prefix included.
    fn message(len: u32) -> Vec<u8> {
        let mut m = vec![0];
        m.extend_from_slice(&len.to_be_bytes());
        m.resize(5 + len as usize, 7);
        m
    }

    #[test]
    fn messages_at_the_limit_pass_in_any_chunking() {
        let body: Vec<u8> = [message(10), message(0), message(10)].concat();
        for size in 1..=body.len() {
            let mut framing = Framing::default();
            for chunk in body.chunks(size) {
                assert_eq!(framing.scan(chunk, 10), None, "chunks of {size}");
            }
            assert_eq!((framing.prefix_len, framing.remaining), (0, 0));
        }
    }

    #[test]
    fn the_first_oversized_prefix_is_found_where_it_starts() {
        let body: Vec<u8> = [message(3), message(11), message(1)].concat();
        let mut framing = Framing::default();
        assert_eq!(
            framing.scan(&body, 10),
            Some(Oversized {
                start: 8,
                bytes: 11
            })
        );
        // A prefix split across chunks: its start is reported as the start of the later chunk.
        for split in 9..13 {
            let mut framing = Framing::default();
            assert_eq!(framing.scan(&body[..split], 10), None, "split at {split}");
            assert_eq!(
                framing.scan(&body[split..], 10),
                Some(Oversized {
                    start: 0,
                    bytes: 11
                }),
                "split at {split}"
            );
        }
    }

    #[test]
    fn the_largest_announced_length_is_read_whole() {
        let mut framing = Framing::default();
        let prefix = [0, 0xff, 0xff, 0xff, 0xff];
        assert_eq!(
            framing.scan(&prefix, u64::from(u32::MAX) - 1),
            Some(Oversized {
                start: 0,
                bytes: u64::from(u32::MAX)
            })
        );
    }
}
