"""Properties of the rules that keep the service inside its boundaries.

* Object keys: whatever text reaches a key (a reference's key, a segment), the result is refused
  or stays under its prefix: no ``..``, no empty or absolute part.
* SSRF: every address in a special-purpose range (an independent list, from the IANA registries)
  is refused, however the URL spells it, before any connection is made (a listening socket on
  127.0.0.1 stands in for an internal service and must see nothing).
"""

from __future__ import annotations

import ipaddress
import posixpath

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from prism_common.references import ReferenceError, is_public_ip, parse_reference
from prism_common.settings import Settings
from prism_common.storage import object_key

from prism_worker.artifacts import item_key, tile_key
from prism_worker.inputs import fetch_url

from .conftest import API_KEYS, WEBHOOK_SECRET

JOB = "0123456789abcdef0123456789abcdef"
FUZZ = settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
tricky = st.one_of(st.text(max_size=40), st.sampled_from(
    ["..", ".", "", "/", "a/../../b", "..%2f..", "\\..\\x", "a\x00b", "/etc/passwd", "~root", "a/./b",
     "....//....//", ".hidden", "x" * 200, "\u2024\u2024", "\uff0e\uff0e"]))


def _plain(key: str, prefix: str) -> bool:
    parts = key.split("/")
    return (key.startswith(prefix) and posixpath.normpath(key) == key
            and all(p not in ("", ".", "..") for p in parts))


@FUZZ
@given(segment=tricky)
def test_object_keys_never_leave_their_prefix(segment, figures):
    figures["inputs tried"] += 1
    for build in (lambda s: object_key("jobs", JOB, s), lambda s: item_key(JOB, 0, s),
                  lambda s: tile_key(JOB, 1, s, 0, 10)):
        try:
            key = build(segment)
        except ValueError:
            continue
        assert _plain(key, f"jobs/{JOB}/"), key
        assert len(key.split("/")) == len(build("x").split("/"))  # the segment stayed one segment


@FUZZ
@given(key=tricky)
def test_s3_references_name_plain_keys_only(key, figures):
    figures["inputs tried"] += 1
    try:
        ref = parse_reference(f"s3://inputs/{key}")
    except ReferenceError:
        return
    assert ref.bucket == "inputs" and _plain(ref.key, ""), ref


# -- SSRF -----------------------------------------------------------------------------------------
SPECIAL = [ipaddress.ip_network(n) for n in (
    "0.0.0.0/8", "10.0.0.0/8", "100.64.0.0/10", "127.0.0.0/8", "169.254.0.0/16", "172.16.0.0/12",
    "192.0.2.0/24", "192.168.0.0/16", "198.18.0.0/15", "198.51.100.0/24", "203.0.113.0/24",
    "224.0.0.0/4", "240.0.0.0/4", "::/128", "::1/128", "fc00::/7", "fe80::/10", "ff00::/8",
    "2001:db8::/32", "64:ff9b:1::/48")]


@FUZZ
@given(data=st.data())
def test_every_special_purpose_address_is_refused(data, figures):
    net = data.draw(st.sampled_from(SPECIAL))
    address = net[data.draw(st.integers(0, net.num_addresses - 1))]
    figures["inputs tried"] += 1
    assert not is_public_ip(str(address)), address
    if address.version == 4:  # also when dressed as IPv6: mapped, NAT64, 6to4, IPv4-compatible
        v4 = int(address)
        for dressed in (f"::ffff:{address}", f"64:ff9b::{address}", f"::{address}",
                        str(ipaddress.IPv6Address((0x2002 << 112) | (v4 << 80) | 1))):
            assert not is_public_ip(dressed), (address, dressed)


@pytest.mark.parametrize("address", ["8.8.8.8", "1.1.1.1", "2606:4700::1111", "::ffff:8.8.8.8",
                                     "64:ff9b::808:808", "2002:808:808::1"])
def test_public_addresses_pass(address):
    assert is_public_ip(address)  # the rule is not "refuse everything"


@pytest.mark.parametrize("host", [
    "2130706433", "0x7f.1", "0177.0.0.1", "127.1", "127.0.0.1.", "[::ffff:127.0.0.1]",
    "[::ffff:7f00:1]", "[::ffff:a9fe:a9fe]", "169.254.169.254", "100.64.0.1", "[fe80::1]", "224.0.0.1",
    "0.0.0.0", "[::]", "localhost"])
def test_loopback_link_local_and_private_spellings_are_refused_unconnected(listener, host, figures):
    port = listener.getsockname()[1]
    name = host.strip("[]").rstrip(".").lower()
    allowed = Settings(api_keys=API_KEYS, webhook_secret=WEBHOOK_SECRET, fetch_max_bytes=1000,
                       fetch_allowed_hosts=[name, host.lower()])  # even when allow-listed
    figures["inputs tried"] += 1
    with pytest.raises(ReferenceError, match=r"private or local|cannot resolve|not on the allow-list"):
        fetch_url(f"https://{host}:{port}/latest/meta-data/", allowed)


@pytest.mark.parametrize("url", ["file:///etc/passwd", "gopher://127.0.0.1:70/", "ftp://127.0.0.1/x",
                                 "http://169.254.169.254/latest/meta-data/", "data:text/plain,hi",
                                 "dict://127.0.0.1:11211/", "ldap://127.0.0.1/", "//127.0.0.1/x"])
def test_other_schemes_are_refused_unconnected(listener, url, figures):
    allowed = Settings(api_keys=API_KEYS, webhook_secret=WEBHOOK_SECRET,
                       fetch_allowed_hosts=["127.0.0.1", "169.254.169.254"], fetch_allow_private=True)
    figures["inputs tried"] += 1
    with pytest.raises(ReferenceError):
        fetch_url(url, allowed)
    with pytest.raises(ReferenceError):
        parse_reference(url)  # and the API refuses them as references in the first place
