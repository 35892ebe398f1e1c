//! What runs when a call's headers arrive, before its body is read: the arrival stamp that
//! deadlines count from, and the bearer-token check.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Instant;

use crate::Error;
use crate::status::to_status;

/// When a call's headers arrived.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Arrived(pub Instant);

/// Runs when a call's headers arrive, before its body is read, for every service but health:
/// stamps the arrival time (the caller's deadline counts from it, see
/// [`crate::service::deadline_of`]) and checks the bearer token (`authorization: Bearer <token>`).
#[derive(Debug, Clone)]
pub(crate) struct Auth {
    pub tokens: Option<Arc<HashSet<String>>>,
}

impl tonic::service::Interceptor for Auth {
    fn call(
        &mut self,
        mut request: tonic::Request<()>,
    ) -> Result<tonic::Request<()>, tonic::Status> {
        request.extensions_mut().insert(Arrived(Instant::now()));
        let Some(tokens) = &self.tokens else {
            return Ok(request);
        };
        let token = request
            .metadata()
            .get("authorization")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| {
                v.strip_prefix("Bearer ")
                    .or_else(|| v.strip_prefix("bearer "))
            })
            .map(str::trim);
        match token {
            Some(t) if tokens.contains(t) => Ok(request),
            _ => Err(to_status(&Error::Unauthenticated)),
        }
    }
}
