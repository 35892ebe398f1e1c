//! PLY reading: any bytes give a cloud or an error; a cloud that was read writes and reads back
//! to the same cloud.
#![no_main]

use landing_recording::ply;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(cloud) = ply::parse(data)
        && cloud.points.iter().flatten().all(|v| v.is_finite())
    {
        let again = ply::parse(&ply::write_binary(&cloud)).expect("our own PLY reads back");
        assert_eq!(again.points, cloud.points);
        assert_eq!(again.classes, cloud.classes);
    }
});
