#!/usr/bin/env bash
# Generates the Python stubs of inspection.v1 with Debian's protoc and grpc_python_plugin
# (packages protobuf-compiler, protobuf-compiler-grpc). Debian 12's python3-grpc-tools cannot
# compile proto3 `optional` fields, which the API uses; protoc 3.21 can.
#   generate_stubs.sh OUT_DIR   -> OUT_DIR/inspection/v1/inspection_pb2.py, inspection_pb2_grpc.py
set -euo pipefail
out="${1:?usage: generate_stubs.sh OUT_DIR}"
proto_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../proto" && pwd)"
mkdir -p "$out"
protoc -I "$proto_root" --python_out="$out" --grpc_out="$out" \
  --plugin=protoc-gen-grpc="$(command -v grpc_python_plugin)" inspection/v1/inspection.proto
echo "stubs in $out/inspection/v1"
