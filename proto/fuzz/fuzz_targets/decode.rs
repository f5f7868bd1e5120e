//! Feeds arbitrary bytes to every message decoder: none may panic, and whatever
//! decodes must survive a re-encode and decode unchanged.
#![no_main]

use libfuzzer_sys::fuzz_target;
use spwi_proto::*;

fn check<M: Message + PartialEq + std::fmt::Debug>(data: &[u8]) {
    if let Ok(m) = decode::<M>(data) {
        assert_eq!(decode::<M>(&encode(&m)).as_ref(), Ok(&m), "decoded value does not round-trip");
    }
}

fuzz_target!(|data: &[u8]| {
    check::<DetectionFrame>(data);
    check::<EmbeddingMsg>(data);
    check::<VoteMsg>(data);
    check::<DecisionMsg>(data);
    check::<BallotsMsg>(data);
    check::<MapMsg>(data);
    check::<HistoryMsg>(data);
    check::<TruthMsg>(data);
});
