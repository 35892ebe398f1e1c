//! Request → validated frame: any bytes, decoded as a `DetectLandingSitesRequest` and converted
//! as the service does. It must give a frame or an error naming a field, never panic.
#![no_main]

use landing_geometry::Params;
use landing_proto::v1::DetectLandingSitesRequest;
use libfuzzer_sys::fuzz_target;
use prost::Message;

fuzz_target!(|data: &[u8]| {
    let Ok(request) = DetectLandingSitesRequest::decode(data) else {
        return;
    };
    if let Err(landing_server::Error::InvalidArgument(violations)) =
        landing_server::convert::request_parts(&request, &Params::default())
    {
        assert!(!violations.is_empty());
        assert!(violations.iter().all(|v| !v.field.is_empty()));
    }
});
