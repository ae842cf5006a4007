#!/bin/sh
# Builds the Rust peers of bench/compare.py (Rapier, Jolt) into bench/peers/target/release. make
# bench runs this first; compare.py skips a peer whose program is missing and says why.
# Needs cargo, and for Jolt (joltc-sys builds JoltC and Jolt's C++ with cmake, and bindgen reads
# its header) cmake, a C++ compiler and libclang with its headers (Debian: apt-get install cmake
# g++ libclang-dev).
# Each peer builds on its own, so one that fails leaves the other. JOBS (default 2) caps the
# compiler processes: the first Jolt build takes minutes.
cd "$(dirname "$0")" || exit 1
if ! command -v cargo >/dev/null; then
    echo "bench/peers: cargo not found, the Rust peers (Rapier, Jolt) are skipped (https://rustup.rs)" >&2
    exit 1
fi
status=0
for peer in rapier_bench rapier_parallel_bench jolt_bench; do
    nice -n 10 cargo build --release --locked --quiet -j "${JOBS:-2}" -p "$peer" \
        || { echo "bench/peers: $peer did not build; compare.py goes on without it" >&2; status=1; }
done
exit $status
