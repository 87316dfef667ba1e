#!/usr/bin/env bash
# Test PKI for the OPC UA gateway test, made with Debian's openssl at run time (nothing committed):
#   grpc-ca.{crt,key}          CA of the gRPC side (as tests/server/test_certs.h: EC P-256)
#   inspectd.{crt,key}         inspectd's server certificate (localhost, 127.0.0.1)
#   gateway-grpc.{crt,key}     the gateway's mTLS client certificate, CN opcua-gateway
#   mes-grpc.{crt,key}         the test's own gRPC client certificate, CN mes-verifier
#   opcua-server.{crt,key}     the gateway's OPC UA application instance certificate (RSA 2048,
#                              SAN URI urn:inspection:opcua-gateway)
#   mes-client.{crt,key}       the test client's application certificate (trusted by the gateway)
#   rogue-client.{crt,key}     another client application certificate, not trusted
#   qa-lead.{crt,key}          an X.509 user certificate (CN qa-lead), trusted as a user
#   make_certs.sh DIR
set -euo pipefail
dir="$1"
mkdir -p "$dir"
cd "$dir"
ossl() { openssl "$@" 2>/dev/null; }

ossl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -keyout grpc-ca.key -out grpc-ca.crt -days 30 \
  -subj "/CN=inspection test CA" -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign"
grpc_leaf() {  # name CN SAN
  ossl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -keyout "$1.key" -out "$1.csr" -subj "/CN=$2"
  printf 'basicConstraints=critical,CA:FALSE\nsubjectAltName=%s\n' "$3" >"$1.ext"
  ossl x509 -req -in "$1.csr" -CA grpc-ca.crt -CAkey grpc-ca.key -CAcreateserial -days 30 -extfile "$1.ext" -out "$1.crt"
  rm -f "$1.csr" "$1.ext"
}
grpc_leaf inspectd localhost "DNS:localhost,IP:127.0.0.1"
grpc_leaf gateway-grpc opcua-gateway "DNS:opcua-gateway"
grpc_leaf mes-grpc mes-verifier "DNS:mes-verifier"

opcua_app() {  # name CN applicationUri
  ossl req -x509 -newkey rsa:2048 -nodes -keyout "$1.key" -out "$1.crt" -days 30 -subj "/CN=$2/O=inspection test" \
    -addext "subjectAltName=URI:$3,DNS:localhost,IP:127.0.0.1" \
    -addext "basicConstraints=critical,CA:FALSE" \
    -addext "keyUsage=critical,digitalSignature,nonRepudiation,keyEncipherment,dataEncipherment" \
    -addext "extendedKeyUsage=serverAuth,clientAuth"
}
opcua_app opcua-server inspect-opcua-gateway urn:inspection:opcua-gateway
opcua_app mes-client mes-client urn:inspection:test:mes-client
opcua_app rogue-client rogue-client urn:inspection:test:rogue-client
opcua_app qa-lead qa-lead urn:inspection:test:qa-lead
