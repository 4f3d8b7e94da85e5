"""One OPC UA client connection with a certificate of its own, for the
certificate trust steps of tests/e2e/opcua.sh.

Usage: opcua_connect.py URL DIR NAME USER PASSWORD
       opcua_connect.py --pem DIR NAME

Makes (once) the client NAME's self-signed certificate DIR/NAME-cert.der
and key DIR/NAME-key.pem, connects with Basic256Sha256 SignAndEncrypt as
USER, reads the server's state and disconnects. Prints "connected" and
exits 0, or prints why and exits 3. With --pem, only makes the certificate
and writes it as PEM to DIR/NAME.crt too (as a client's maker hands one
over).
"""

import asyncio
import sys
from pathlib import Path

from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID


async def make_cert(folder, name):
    key, cert = Path(folder) / f"{name}-key.pem", Path(folder) / f"{name}-cert.der"
    await setup_self_signed_certificate(
        key, cert, f"urn:gridscada-tests:{name}", "localhost", [ExtendedKeyUsageOID.CLIENT_AUTH],
        {"countryName": "EU", "organizationName": "gridscada tests", "commonName": name},
    )
    return key, cert


async def pem(folder, name):
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding

    _, cert = await make_cert(folder, name)
    der = x509.load_der_x509_certificate(cert.read_bytes())
    (Path(folder) / f"{name}.crt").write_bytes(der.public_bytes(Encoding.PEM))
    return 0


async def main(url, folder, name, user, password):
    key, cert = await make_cert(folder, name)
    uri = f"urn:gridscada-tests:{name}"
    c = Client(url, timeout=10)
    c.application_uri = uri
    c.set_user(user)
    c.set_password(password)
    await c.set_security(
        SecurityPolicyBasic256Sha256, str(cert), str(key),
        mode=ua.MessageSecurityMode.SignAndEncrypt,
    )
    try:
        await asyncio.wait_for(c.connect(), 20)
    except Exception as e:  # the refusal's status, whatever asyncua raises it as
        print(f"refused: {type(e).__name__}: {e}")
        return 3
    try:
        state = await c.get_node(ua.ObjectIds.Server_ServerStatus_State).read_value()
        print(f"connected (server state {state})")
        return 0
    finally:
        await c.disconnect()


if __name__ == "__main__":
    if sys.argv[1] == "--pem":
        sys.exit(asyncio.run(pem(*sys.argv[2:4])))
    sys.exit(asyncio.run(main(*sys.argv[1:6])))
