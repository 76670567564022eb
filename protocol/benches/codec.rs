//! Decode and encode throughput of RO_ACCESS_REPORT frames (1, 10 and 100 tag reports each),
//! in tag reports per second: the full typed decode (`decode`), the borrowed tag-read walk
//! (`tag_reads`) and encoding. `scripts/bench-codec` runs this and the sllurp baseline together.

use bytes::BytesMut;
use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use llrp::sample::benchmark_report;
use llrp::Message;

fn codec(c: &mut Criterion) {
    let mut group = c.benchmark_group("ro_access_report");
    for n in [1usize, 10, 100] {
        let msg = benchmark_report(n, 7);
        let frame = msg.to_bytes();
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::new("decode", n), &frame, |b, f| {
            b.iter(|| Message::decode(black_box(f)).expect("valid frame"))
        });
        group.bench_with_input(BenchmarkId::new("tag_reads", n), &frame, |b, f| {
            b.iter(|| {
                let mut phase = 0u32;
                for r in llrp::reads::tag_reads(black_box(f)).expect("valid frame") {
                    phase += u32::from(r.expect("valid read").phase_angle.unwrap_or(0));
                }
                phase
            })
        });
        let mut buf = BytesMut::with_capacity(frame.len());
        group.bench_with_input(BenchmarkId::new("encode", n), &msg, |b, m| {
            b.iter(|| {
                buf.clear();
                black_box(m).encode(&mut buf);
                black_box(buf.len())
            })
        });
    }
    group.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
