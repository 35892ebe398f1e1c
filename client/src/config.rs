//! Connection settings: endpoint, token, TLS, timeouts and the retry policy.

use std::path::Path;
use std::time::Duration;

use crate::ClientError;

/// The default server address, matching the server's default listen address.
pub const DEFAULT_SERVER: &str = "http://127.0.0.1:50051";

/// Everything needed to reach a server. `Default` talks plain HTTP/2 to [`DEFAULT_SERVER`].
#[derive(Debug, Clone)]
pub struct ClientConfig {
    /// `http://host:port` or `https://host:port`.
    pub endpoint: String,
    /// Bearer token sent as `authorization: Bearer <token>` on every call.
    pub token: Option<String>,
    /// TLS settings; required for `https://` endpoints.
    pub tls: Option<TlsConfig>,
    /// Limit on establishing the connection.
    pub connect_timeout: Duration,
    /// Deadline of each unary call (sent to the server as `grpc-timeout`). Streams have none.
    pub request_timeout: Option<Duration>,
    /// Retries of unary calls.
    pub retry: RetryPolicy,
    /// Largest response the client accepts.
    pub max_response_bytes: usize,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            endpoint: DEFAULT_SERVER.to_owned(),
            token: None,
            tls: None,
            connect_timeout: Duration::from_secs(5),
            request_timeout: Some(Duration::from_secs(30)),
            retry: RetryPolicy::default(),
            max_response_bytes: 64 << 20,
        }
    }
}

impl ClientConfig {
    /// The default configuration for this endpoint.
    pub fn new(endpoint: impl Into<String>) -> Self {
        Self {
            endpoint: endpoint.into(),
            ..Self::default()
        }
    }

    /// Sets the bearer token.
    pub fn with_token(mut self, token: impl Into<String>) -> Self {
        self.token = Some(token.into());
        self
    }

    /// Sets the TLS settings.
    pub fn with_tls(mut self, tls: TlsConfig) -> Self {
        self.tls = Some(tls);
        self
    }
}

/// TLS material, PEM-encoded.
#[derive(Debug, Clone, Default)]
pub struct TlsConfig {
    /// The CA that signed the server's certificate.
    pub ca_cert_pem: Option<Vec<u8>>,
    /// Client certificate and key, for servers that require mutual TLS.
    pub client_cert_pem: Option<Vec<u8>>,
    /// Key of `client_cert_pem`.
    pub client_key_pem: Option<Vec<u8>>,
    /// Name to verify the server certificate against, when it differs from the URL's host.
    pub domain_name: Option<String>,
}

impl TlsConfig {
    /// Reads the PEM files; `None` paths are left unset.
    pub fn from_files(
        ca_cert: Option<&Path>,
        client_cert: Option<&Path>,
        client_key: Option<&Path>,
    ) -> Result<Self, ClientError> {
        let read = |p: Option<&Path>| -> Result<Option<Vec<u8>>, ClientError> {
            p.map(|p| std::fs::read(p).map_err(|e| ClientError::io(p, e)))
                .transpose()
        };
        Ok(Self {
            ca_cert_pem: read(ca_cert)?,
            client_cert_pem: read(client_cert)?,
            client_key_pem: read(client_key)?,
            domain_name: None,
        })
    }
}

/// Exponential backoff for unary calls. Only `UNAVAILABLE` and `RESOURCE_EXHAUSTED` are retried
/// (detection is a pure function of the frame, so re-sending is safe); a server's `RetryInfo`
/// delay replaces the computed backoff. Frames on a stream are never re-sent.
#[derive(Debug, Clone, PartialEq)]
pub struct RetryPolicy {
    /// Total attempts, the first included; 1 disables retries.
    pub max_attempts: u32,
    /// Backoff before the second attempt.
    pub initial_backoff: Duration,
    /// Upper bound of any one wait, including server-requested ones.
    pub max_backoff: Duration,
    /// Growth factor of the backoff per attempt.
    pub multiplier: f64,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        Self {
            max_attempts: 5,
            initial_backoff: Duration::from_millis(50),
            max_backoff: Duration::from_secs(5),
            multiplier: 2.0,
        }
    }
}

impl RetryPolicy {
    /// No retries.
    pub fn none() -> Self {
        Self {
            max_attempts: 1,
            ..Self::default()
        }
    }

    /// Whether a call that failed with `code` may be sent again: UNAVAILABLE, and
    /// RESOURCE_EXHAUSTED when the server said when to retry (`retry_after`, its overload
    /// refusals); a request over the server's size limit is RESOURCE_EXHAUSTED without one, and
    /// sending it again cannot succeed.
    pub fn is_retryable(code: tonic::Code, retry_after: Option<Duration>) -> bool {
        match code {
            tonic::Code::Unavailable => true,
            tonic::Code::ResourceExhausted => retry_after.is_some(),
            _ => false,
        }
    }

    /// The wait before attempt `attempt + 1` (attempt counts from 1), given the server's request.
    /// Computed waits are jittered down by up to half, with `jitter` in `[0, 1)`, so that many
    /// clients refused at once do not come back at once.
    pub fn backoff(&self, attempt: u32, server_delay: Option<Duration>, jitter: f64) -> Duration {
        if let Some(d) = server_delay {
            return d.min(self.max_backoff);
        }
        let exp = self
            .multiplier
            .max(1.0)
            .powi(attempt.saturating_sub(1).min(64) as i32);
        let full = self.initial_backoff.as_secs_f64() * exp;
        let capped = full.min(self.max_backoff.as_secs_f64());
        Duration::from_secs_f64(capped * (1.0 - 0.5 * jitter.clamp(0.0, 1.0)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_grows_and_is_capped() {
        let p = RetryPolicy::default();
        assert_eq!(p.backoff(1, None, 0.0), Duration::from_millis(50));
        assert_eq!(p.backoff(2, None, 0.0), Duration::from_millis(100));
        assert_eq!(p.backoff(3, None, 0.0), Duration::from_millis(200));
        assert_eq!(p.backoff(30, None, 0.0), Duration::from_secs(5));
        assert_eq!(p.backoff(1, None, 1.0), Duration::from_millis(25));
    }

    #[test]
    fn server_delay_wins_but_is_capped() {
        let p = RetryPolicy::default();
        assert_eq!(
            p.backoff(1, Some(Duration::from_millis(700)), 0.3),
            Duration::from_millis(700)
        );
        assert_eq!(
            p.backoff(1, Some(Duration::from_secs(600)), 0.0),
            Duration::from_secs(5)
        );
    }

    #[test]
    fn only_overload_and_unavailable_are_retried() {
        let later = Some(Duration::from_millis(50));
        assert!(RetryPolicy::is_retryable(tonic::Code::Unavailable, None));
        assert!(RetryPolicy::is_retryable(
            tonic::Code::ResourceExhausted,
            later
        ));
        assert!(!RetryPolicy::is_retryable(
            tonic::Code::ResourceExhausted,
            None
        ));
        assert!(!RetryPolicy::is_retryable(
            tonic::Code::InvalidArgument,
            later
        ));
        assert!(!RetryPolicy::is_retryable(
            tonic::Code::DeadlineExceeded,
            None
        ));
        assert!(!RetryPolicy::is_retryable(tonic::Code::Internal, None));
    }

    #[test]
    fn missing_certificate_file_names_the_path() {
        let err =
            TlsConfig::from_files(Some(Path::new("/nonexistent/ca.pem")), None, None).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/ca.pem"), "{err}");
    }
}
