#!/usr/bin/env python3
"""A test IED for the IEC 61850 MMS client: libiec61850 (pyiec61850-ng, GPL, a test
peer only, never linked into the product) serving a model built from ONE spec, and
the IEC 61850-6 SCL of that same model for the SCL importer.

The libiec61850 model is built from ``DEFAULT_SPEC`` with the CDC_*_create helpers;
``write_scl`` builds that same model in-process and walks it, so the SCL's
DataTypeTemplates are exactly what the server serves (names, FCs, types, order,
trigger options).

Script mode::

    python3 iec61850_peer.py --port 10102 [--host 127.0.0.1] [--scl OUT.scd] [--ied TEST]

prints ``{"ready": true, "port": P}`` and then answers newline JSON commands on stdin,
one JSON line each (see ``Peer.command``): set, get, interlock, controls, burst,
values, quit. Anything written to the process's fd 1 by C code goes to stderr; only
the JSON answers go to stdout.

Quality ints (``"q"`` in set, quality values in get/values) use libiec61850's
Quality encoding: bit i is bit i of the IEC quality bit-string, so 0 = good,
2 = invalid, 3 = questionable, 64 = failure, 128 = oldData, 2048 = test,
4096 = operatorBlocked. Dbpos ints: 0 intermediate, 1 off, 2 on, 3 bad.
Timestamps are unix float seconds.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import signal
import sys
import threading
import time
import xml.etree.ElementTree as ET
from typing import Any, Optional

import pyiec61850.pyiec61850 as L

M = L.toModelNode

# ---------------------------------------------------------------------------------
# The spec
# ---------------------------------------------------------------------------------

# ctl names of the spec -> (libiec61850 CDC option, ctlModel enum value)
CTL = {
    "status-only": (L.CDC_CTL_MODEL_NONE, 0),
    "direct-with-normal-security": (L.CDC_CTL_MODEL_DIRECT_NORMAL, 1),
    "sbo-with-normal-security": (L.CDC_CTL_MODEL_SBO_NORMAL, 2),
    "direct-with-enhanced-security": (L.CDC_CTL_MODEL_DIRECT_ENHANCED, 3),
    "sbo-with-enhanced-security": (L.CDC_CTL_MODEL_SBO_ENHANCED, 4),
}
LIB_CTL_MODEL = {
    1: L.CONTROL_MODEL_DIRECT_NORMAL,
    2: L.CONTROL_MODEL_SBO_NORMAL,
    3: L.CONTROL_MODEL_DIRECT_ENHANCED,
    4: L.CONTROL_MODEL_SBO_ENHANCED,
}

# Data object entries: name, cdc, optional "ctl", "sdos" (WYE), "init" {DA path: value}
# (enum values as ints; they become DOI/DAI Val in the SCL and initial server values)
# and "type" (preferred DOType id).
DEFAULT_SPEC: dict = {
    "ied": "TEST",
    "manufacturer": "gridscada",
    "ied_type": "TestIED",
    "config_version": "1.0",
    "ap": "AP1",
    "subnetwork": "StationBus",
    "host": "127.0.0.1",
    "port": 102,
    "ldevices": [
        {
            "inst": "LD0",
            "lns": [
                {
                    "lnClass": "LLN0", "inst": "", "prefix": "",
                    "dos": [
                        {"name": "Mod", "cdc": "ENC", "ctl": "status-only", "init": {"stVal": 1}},
                        {"name": "Beh", "cdc": "ENS", "init": {"stVal": 1}},
                        {"name": "Health", "cdc": "ENS", "init": {"stVal": 1}},
                        {"name": "NamPlt", "cdc": "LPL",
                         "init": {"vendor": "gridscada", "swRev": "1.6.1", "d": "gridscada test IED"}},
                    ],
                    "datasets": [
                        {"name": "Events", "members": [
                            "GGIO1$ST$Ind1", "CSWI1$ST$Pos", "CSWI2$ST$Pos", "CSWI3$ST$Pos",
                            "CSWI4$ST$Pos", "GGIO1$ST$SPCSO1", "MMXU1$MX$TotW", "MMTR1$ST$TotWh",
                        ]},
                        {"name": "Measurements", "members": [
                            "MMXU1$MX$TotW$mag", "MMXU1$MX$PhV$phsA", "GGIO1$MX$AnIn1",
                            "MMTR1$ST$TotWh$actVal",
                        ]},
                    ],
                    "rcbs": [
                        {"name": "brcb01", "rptID": "brcb01", "buffered": True, "datSet": "Events",
                         "confRev": 1, "bufTime": 50, "intgPd": 0,
                         "trgOps": ["dchg", "qchg", "gi", "period"],
                         "optFields": ["seqNum", "timeStamp", "dataSet", "reasonCode", "dataRef",
                                       "entryID", "configRef", "bufOvfl"]},
                        {"name": "urcb01", "rptID": "urcb01", "buffered": False, "datSet": "Events",
                         "confRev": 1, "bufTime": 50, "intgPd": 0,
                         "trgOps": ["dchg", "qchg", "gi", "period"],
                         "optFields": ["seqNum", "timeStamp", "dataSet", "reasonCode", "dataRef",
                                       "configRef"]},
                    ],
                },
                {
                    "lnClass": "MMXU", "inst": "1", "prefix": "",
                    "dos": [
                        {"name": "Beh", "cdc": "ENS", "init": {"stVal": 1}},
                        {"name": "TotW", "cdc": "MV", "units": True,
                         "init": {"mag.f": 1234.5, "units.SIUnit": 38, "units.multiplier": 0}},
                        {"name": "PhV", "cdc": "WYE", "sdos": ["phsA"],
                         "init": {"phsA.cVal.mag.f": 230.1, "phsA.units.SIUnit": 29,
                                  "phsA.units.multiplier": 3}},
                    ],
                },
                {
                    "lnClass": "MMTR", "inst": "1", "prefix": "",
                    "dos": [
                        {"name": "Beh", "cdc": "ENS", "init": {"stVal": 1}},
                        {"name": "TotWh", "cdc": "BCR", "units": True,
                         "init": {"actVal": 100000, "pulsQty": 1.0, "units.SIUnit": 72,
                                  "units.multiplier": 3}},
                    ],
                },
                {
                    "lnClass": "GGIO", "inst": "1", "prefix": "",
                    "dos": [
                        {"name": "Beh", "cdc": "ENS", "init": {"stVal": 1}},
                        {"name": "AnIn1", "cdc": "MV", "init": {"mag.f": 42.0}},
                        {"name": "Ind1", "cdc": "SPS", "init": {"stVal": False}},
                        {"name": "SPCSO1", "cdc": "SPC", "ctl": "direct-with-normal-security",
                         "init": {"stVal": False}},
                    ],
                },
                {"lnClass": "CSWI", "inst": "1", "prefix": "", "dos": [
                    {"name": "Beh", "cdc": "ENS", "init": {"stVal": 1}},
                    {"name": "Pos", "cdc": "DPC", "ctl": "sbo-with-enhanced-security",
                     "init": {"stVal": 1, "sboTimeout": 30000, "sboClass": 0}}]},
                {"lnClass": "CSWI", "inst": "2", "prefix": "", "dos": [
                    {"name": "Beh", "cdc": "ENS", "init": {"stVal": 1}},
                    {"name": "Pos", "cdc": "DPC", "ctl": "direct-with-normal-security",
                     "init": {"stVal": 1}}]},
                {"lnClass": "CSWI", "inst": "3", "prefix": "", "dos": [
                    {"name": "Beh", "cdc": "ENS", "init": {"stVal": 1}},
                    {"name": "Pos", "cdc": "DPC", "ctl": "sbo-with-normal-security",
                     "init": {"stVal": 1, "sboTimeout": 30000, "sboClass": 0}}]},
                {"lnClass": "CSWI", "inst": "4", "prefix": "", "dos": [
                    {"name": "Beh", "cdc": "ENS", "init": {"stVal": 1}},
                    {"name": "Pos", "cdc": "DPC", "ctl": "direct-with-enhanced-security",
                     "init": {"stVal": 1}}]},
            ],
        }
    ],
}

TRG_BITS = {"dchg": L.TRG_OPT_DATA_CHANGED, "qchg": L.TRG_OPT_QUALITY_CHANGED,
            "dupd": L.TRG_OPT_DATA_UPDATE, "period": L.TRG_OPT_INTEGRITY, "gi": L.TRG_OPT_GI}
OPT_BITS = {"seqNum": L.RPT_OPT_SEQ_NUM, "timeStamp": L.RPT_OPT_TIME_STAMP,
            "reasonCode": L.RPT_OPT_REASON_FOR_INCLUSION, "dataSet": L.RPT_OPT_DATA_SET,
            "dataRef": L.RPT_OPT_DATA_REFERENCE, "bufOvfl": L.RPT_OPT_BUFFER_OVERFLOW,
            "entryID": L.RPT_OPT_ENTRY_ID, "configRef": L.RPT_OPT_CONF_REV}

FC_NAMES = {v: k[len("IEC61850_FC_"):] for k, v in vars(L).items()
            if k.startswith("IEC61850_FC_") and isinstance(v, int) and k not in ("IEC61850_FC_ALL", "IEC61850_FC_NONE")}
FC_CODES = {v: k for k, v in FC_NAMES.items()}


def ln_name(ln: dict) -> str:
    return ln.get("prefix", "") + ln["lnClass"] + ln.get("inst", "")


def domain_of(spec: dict, ld: dict) -> str:
    return spec["ied"] + ld["inst"]


def with_ied(spec: dict, ied: str) -> dict:
    s = copy.deepcopy(spec)
    s["ied"] = ied
    return s


# ---------------------------------------------------------------------------------
# The libiec61850 model
# ---------------------------------------------------------------------------------

def _add_units(do_node) -> None:
    L.DataAttribute_create("units", do_node, L.IEC61850_CONSTRUCTED, L.IEC61850_FC_CF, 0, 0, 0)
    units = [c for c in children(do_node) if c.name == "units"][-1]  # as a ModelNode
    L.DataAttribute_create("SIUnit", units, L.IEC61850_ENUMERATED, L.IEC61850_FC_CF, L.TRG_OPT_DATA_CHANGED, 0, 0)
    L.DataAttribute_create("multiplier", units, L.IEC61850_ENUMERATED, L.IEC61850_FC_CF, L.TRG_OPT_DATA_CHANGED, 0, 0)


def _create_do(do: dict, parent) -> Any:
    cdc, name = do["cdc"], do["name"]
    ctl_opt = CTL[do.get("ctl", "status-only")][0]
    if ctl_opt in (L.CDC_CTL_MODEL_SBO_NORMAL, L.CDC_CTL_MODEL_SBO_ENHANCED):
        ctl_opt |= (L.CDC_CTL_MODEL_HAS_CANCEL | L.CDC_CTL_OPTION_ORIGIN | L.CDC_CTL_OPTION_CTL_NUM
                    | L.CDC_CTL_OPTION_ST_SELD | L.CDC_CTL_OPTION_SBO_TIMEOUT | L.CDC_CTL_OPTION_SBO_CLASS)
    elif ctl_opt != L.CDC_CTL_MODEL_NONE:
        ctl_opt |= L.CDC_CTL_OPTION_ORIGIN | L.CDC_CTL_OPTION_CTL_NUM
        if ctl_opt & L.CDC_CTL_MODEL_DIRECT_ENHANCED == L.CDC_CTL_MODEL_DIRECT_ENHANCED:
            ctl_opt |= L.CDC_CTL_MODEL_HAS_CANCEL
    if cdc == "MV":
        node = L.CDC_MV_create(name, parent, 0, False)
    elif cdc == "SPS":
        node = L.CDC_SPS_create(name, parent, 0)
    elif cdc == "BCR":
        node = L.CDC_BCR_create(name, parent, 0)
    elif cdc == "ENS":
        node = L.CDC_ENS_create(name, parent, 0)
    elif cdc == "ENC":
        node = L.CDC_ENC_create(name, parent, 0, ctl_opt)
    elif cdc == "LPL":
        node = L.CDC_LPL_create(name, parent, L.CDC_OPTION_DESC)
    elif cdc == "DPC":
        node = L.CDC_DPC_create(name, parent, 0, ctl_opt)
    elif cdc == "SPC":
        node = L.CDC_SPC_create(name, parent, 0, ctl_opt)
    elif cdc == "CMV":
        node = L.CDC_CMV_create(name, parent, 0)
    elif cdc == "WYE":
        node = L.DataObject_create(name, parent, 0)
        for sdo in do.get("sdos", ["phsA", "phsB", "phsC"]):
            sub = _create_do({"name": sdo, "cdc": "CMV", "units": True}, M(node))
        return node
    else:
        raise ValueError(f"unsupported cdc {cdc}")
    if do.get("units"):
        _add_units(M(node))
    if do.get("ctl") in ("sbo-with-normal-security", "sbo-with-enhanced-security"):
        # libiec61850 1.6.1's CDC_DPC_create ignores CDC_CTL_OPTION_SBO_TIMEOUT/SBO_CLASS
        have = {c.name for c in children(M(node))}
        if "sboTimeout" not in have:
            L.DataAttribute_create("sboTimeout", M(node), L.IEC61850_INT32U, L.IEC61850_FC_CF,
                                   L.TRG_OPT_DATA_CHANGED, 0, 0)
        if "sboClass" not in have:
            L.DataAttribute_create("sboClass", M(node), L.IEC61850_ENUMERATED, L.IEC61850_FC_CF,
                                   L.TRG_OPT_DATA_CHANGED, 0, 0)
    return node


def build_model(spec: dict):
    """The libiec61850 IedModel for spec (no server yet)."""
    model = L.IedModel_create(spec["ied"])
    for ld in spec["ldevices"]:
        ldn = L.LogicalDevice_create(ld["inst"], model)
        lns = {}
        for ln in ld["lns"]:
            lnn = L.LogicalNode_create(ln_name(ln), ldn)
            lns[ln_name(ln)] = lnn
            for do in ln["dos"]:
                _create_do(do, M(lnn))
        for ln in ld["lns"]:
            lnn = lns[ln_name(ln)]
            for ds in ln.get("datasets", []):
                dsn = L.DataSet_create(ds["name"], lnn)
                for member in ds["members"]:
                    L.DataSetEntry_create(dsn, member, -1, None)
            for rc in ln.get("rcbs", []):
                trg = sum(TRG_BITS[t] for t in rc["trgOps"])
                opt = sum(OPT_BITS[o] for o in rc["optFields"])
                L.ReportControlBlock_create(rc["name"], lnn, rc["rptID"], rc["buffered"], rc["datSet"],
                                            rc["confRev"], trg, opt, rc["bufTime"], rc["intgPd"])
    return model


def children(node):
    c = node.firstChild
    while c is not None:
        yield c
        c = c.sibling


def leaves(node, path=""):
    """(dotted path, DataAttribute) of every leaf data attribute under node."""
    for c in children(node):
        p = f"{path}.{c.name}" if path else c.name
        if c.modelType == L.DataAttributeModelType and c.firstChild is None:
            yield p, L.toDataAttribute(c)
        else:
            yield from leaves(c, p)


# ---------------------------------------------------------------------------------
# MmsValue <-> JSON
# ---------------------------------------------------------------------------------

def ts_seconds(mms) -> float:
    ts = L.Timestamp_create()
    try:
        L.Timestamp_fromMmsValue(ts, mms)
        return L.Timestamp_getTimeInNs(ts) / 1e9
    finally:
        L.Timestamp_destroy(ts)


def to_json(da, mms=None) -> Any:
    if da.type == L.IEC61850_CONSTRUCTED or da.firstChild is not None:
        return {c.name: to_json(L.toDataAttribute(c)) for c in children(da)}
    mms = da.mmsValue if mms is None else mms
    if mms is None:
        return None
    t = da.type
    mt = L.MmsValue_getType(mms)
    if t == L.IEC61850_CODEDENUM:
        return int(L.Dbpos_fromMmsValue(mms))
    if t == L.IEC61850_QUALITY:
        return int(L.Quality_fromMmsValue(mms))
    if mt == L.MMS_BOOLEAN:
        return bool(L.MmsValue_getBoolean(mms))
    if mt == L.MMS_FLOAT:
        return float(L.MmsValue_toDouble(mms))
    if mt == L.MMS_INTEGER:
        return int(L.MmsValue_toInt64(mms))
    if mt == L.MMS_UNSIGNED:
        return int(L.MmsValue_toUint32(mms))
    if mt == L.MMS_UTC_TIME:
        return ts_seconds(mms)
    if mt in (L.MMS_VISIBLE_STRING, L.MMS_STRING):
        return L.MmsValue_toString(mms)
    if mt == L.MMS_BIT_STRING:
        return "".join("1" if L.MmsValue_getBitStringBit(mms, i) else "0"
                       for i in range(L.MmsValue_getBitStringSize(mms)))
    if mt == L.MMS_OCTET_STRING:
        return bytes(L.MmsValue_getOctetStringOctet(mms, i)
                     for i in range(L.MmsValue_getOctetStringSize(mms))).hex()
    if mt == L.MMS_BINARY_TIME:
        return int(L.MmsValue_getBinaryTimeAsUtcMs(mms)) / 1000.0
    return L.MmsValue_getTypeString(mms)


# ---------------------------------------------------------------------------------
# The server
# ---------------------------------------------------------------------------------

# ControlAction_getOrIdent(action, int* size) has no usable SWIG wrapper (passing None
# for the int* crashes libiec61850), so it is called through ctypes on the same library.
def _load_libiec61850():
    import ctypes
    import glob
    base = os.path.dirname(os.path.dirname(L.__file__))
    for path in glob.glob(os.path.join(base, "pyiec61850_ng.libs", "libiec61850*.so*")):
        lib = ctypes.CDLL(path)
        f = lib.ControlAction_getOrIdent
        f.restype = ctypes.POINTER(ctypes.c_uint8)
        f.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)]
        return ctypes, f
    return ctypes, None


_CT, _GET_OR_IDENT = _load_libiec61850()


def _or_ident(act) -> Optional[bytes]:
    if _GET_OR_IDENT is None:
        return None
    try:
        size = _CT.c_int(0)
        ptr = _GET_OR_IDENT(_CT.c_void_p(int(act)), _CT.byref(size))
        return bytes(ptr[: size.value]) if ptr and size.value > 0 else b""
    except Exception:
        return None


class _Check(L.CheckHandlerForPython):
    """Runs on select (SBO/SBOw) and on operate: refuses close (True) while interlocked."""

    def trigger(self):
        peer, ref = self.peer, self.ref
        act = self._libiec61850_control_action
        try:
            val = self._libiec61850_mms_value
            ctl_val = L.MmsValue_getBoolean(val) if val is not None and L.MmsValue_getType(val) == L.MMS_BOOLEAN else None
            entry = peer._action_entry(ref, act, ctl_val)
            entry["test"] = bool(self._libiec61850_test)
            entry["interlock_check"] = bool(self._libiec61850_interlock_check)
            if peer.interlock and ctl_val is True:
                L.ControlAction_setAddCause(act, L.ADD_CAUSE_BLOCKED_BY_INTERLOCKING)
                self._libiec61850_check_handler_result = L.CONTROL_OBJECT_ACCESS_DENIED
                entry.update(accepted=False, add_cause=int(L.ADD_CAUSE_BLOCKED_BY_INTERLOCKING),
                             cause="blocked-by-interlocking")
            else:
                self._libiec61850_check_handler_result = L.CONTROL_ACCEPTED
                entry["accepted"] = True
            peer._log(entry)
        except Exception as e:  # never let an exception cross into libiec61850
            print(f"check handler error: {e!r}", file=sys.stderr)
            self._libiec61850_check_handler_result = L.CONTROL_ACCEPTED


class _Wait(L.WaitForExecutionHandlerForPython):
    def trigger(self):
        try:
            self.peer._note_synchro(self.ref, bool(self._libiec61850_synchro_check))
        except Exception as e:
            print(f"wait handler error: {e!r}", file=sys.stderr)
        self._libiec61850_control_handler_result = L.CONTROL_RESULT_OK


class _Control(L.ControlHandlerForPython):
    """Executes an accepted operate: stVal follows ctlVal, with a fresh t."""

    def trigger(self):
        peer, ref = self.peer, self.ref
        try:
            val = self._libiec61850_mms_value
            on = bool(L.MmsValue_getBoolean(val))
            st = peer.node(ref + ".stVal")
            tda = peer.node(ref + ".t")
            if self.cdc == "DPC":
                L.IedServer_updateDbposValue(peer.srv, st, L.DBPOS_ON if on else L.DBPOS_OFF)
            else:
                L.IedServer_updateBooleanAttributeValue(peer.srv, st, on)
            t_set = peer._set_ts(tda, time.time())
            peer._log({"ref": ref, "action": "execute", "ctlVal": on,
                       "ctlNum": int(L.ControlAction_getCtlNum(self._libiec61850_control_action)),
                       "test": bool(self._libiec61850_test), "t": t_set})
            self._libiec61850_control_handler_result = L.CONTROL_RESULT_OK
        except Exception as e:
            print(f"control handler error: {e!r}", file=sys.stderr)
            self._libiec61850_control_handler_result = L.CONTROL_RESULT_FAILED


def _check_value(da, value) -> None:
    """Refuse a value that does not fit da before anything is touched."""
    t = da.type
    if t == L.IEC61850_CONSTRUCTED or da.firstChild is not None:
        raise ValueError("set a leaf attribute, not a structure")
    if t == L.IEC61850_BOOLEAN and not isinstance(value, (bool, int)):
        raise ValueError("boolean expected")
    if t == L.IEC61850_CODEDENUM and not (isinstance(value, int) and 0 <= value <= 3):
        raise ValueError("dbpos is an int 0..3")
    if t in (L.IEC61850_FLOAT32, L.IEC61850_FLOAT64, L.IEC61850_TIMESTAMP) and (
            isinstance(value, bool) or not isinstance(value, (int, float))):
        raise ValueError("number expected")
    if t in (L.IEC61850_INT8, L.IEC61850_INT16, L.IEC61850_INT32, L.IEC61850_INT64, L.IEC61850_ENUMERATED,
             L.IEC61850_INT8U, L.IEC61850_INT16U, L.IEC61850_INT24U, L.IEC61850_INT32U,
             L.IEC61850_QUALITY) and (isinstance(value, bool) or not isinstance(value, int)):
        raise ValueError("integer expected")


class Peer:
    def __init__(self, spec: dict):
        self.spec = spec
        self.model = build_model(spec)
        self.srv = None
        self.interlock = False
        self.actions: list = []
        self._lock = threading.Lock()
        self._subs: list = []
        self._handlers: list = []

    # --- model access ---
    def node(self, ref: str):
        ref = ref.split("[", 1)[0].strip()
        n = L.IedModel_getModelNodeByObjectReference(self.model, ref)
        if n is None:
            raise KeyError(f"no such object reference {ref}")
        if n.modelType != L.DataAttributeModelType:
            raise KeyError(f"{ref} is not a data attribute")
        return L.toDataAttribute(n)

    def _ts_of(self, ref: str):
        """The .t and .q of the FCD holding ref (walk up until a parent has a t sibling)."""
        ref = ref.split("[", 1)[0]
        dom, rest = ref.split("/", 1)
        parts = rest.split(".")
        for i in range(len(parts) - 1, 0, -1):
            base = dom + "/" + ".".join(parts[:i])
            t = L.IedModel_getModelNodeByObjectReference(self.model, base + ".t")
            if t is not None and t.modelType == L.DataAttributeModelType:
                q = L.IedModel_getModelNodeByObjectReference(self.model, base + ".q")
                return L.toDataAttribute(t), (L.toDataAttribute(q) if q is not None else None)
        return None, None

    def _set_ts(self, da, t: float) -> float:
        ts = L.Timestamp_create()
        try:
            L.Timestamp_setTimeInNanoseconds(ts, int(round(t * 1e9)))
            L.Timestamp_setLeapSecondKnown(ts, True)
            L.Timestamp_setSubsecondPrecision(ts, 10)
            L.IedServer_updateTimestampAttributeValue(self.srv, da, ts)
        finally:
            L.Timestamp_destroy(ts)
        return ts_seconds(da.mmsValue)

    def _set_value(self, da, value) -> None:
        t = da.type
        if t == L.IEC61850_BOOLEAN:
            if not isinstance(value, (bool, int)):
                raise ValueError("boolean expected")
            L.IedServer_updateBooleanAttributeValue(self.srv, da, bool(value))
        elif t in (L.IEC61850_FLOAT32, L.IEC61850_FLOAT64):
            L.IedServer_updateFloatAttributeValue(self.srv, da, float(value))
        elif t == L.IEC61850_CODEDENUM:
            v = int(value)
            if not 0 <= v <= 3:
                raise ValueError("dbpos is 0..3")
            L.IedServer_updateDbposValue(self.srv, da, v)
        elif t == L.IEC61850_QUALITY:
            L.IedServer_updateQuality(self.srv, da, int(value))
        elif t in (L.IEC61850_INT64,):
            L.IedServer_updateInt64AttributeValue(self.srv, da, int(value))
        elif t in (L.IEC61850_INT8, L.IEC61850_INT16, L.IEC61850_INT32, L.IEC61850_ENUMERATED):
            L.IedServer_updateInt32AttributeValue(self.srv, da, int(value))
        elif t in (L.IEC61850_INT8U, L.IEC61850_INT16U, L.IEC61850_INT24U, L.IEC61850_INT32U):
            L.IedServer_updateUnsignedAttributeValue(self.srv, da, int(value))
        elif t == L.IEC61850_TIMESTAMP:
            self._set_ts(da, float(value))
        elif t in (L.IEC61850_VISIBLE_STRING_32, L.IEC61850_VISIBLE_STRING_64, L.IEC61850_VISIBLE_STRING_65,
                   L.IEC61850_VISIBLE_STRING_129, L.IEC61850_VISIBLE_STRING_255, L.IEC61850_UNICODE_STRING_255):
            L.IedServer_updateVisibleStringAttributeValue(self.srv, da, str(value))
        else:
            raise ValueError(f"cannot set an attribute of libiec61850 type {t}")

    def set(self, ref: str, value, q: Optional[int] = None, t: Optional[float] = None) -> float:
        da = self.node(ref)
        _check_value(da, value)
        tda, qda = self._ts_of(ref)
        L.IedServer_lockDataModel(self.srv)
        try:
            t_set = None
            if tda is not None and da.type != L.IEC61850_TIMESTAMP:
                t_set = self._set_ts(tda, time.time() if t is None else float(t))
            if q is not None and qda is not None and da.type != L.IEC61850_QUALITY:
                L.IedServer_updateQuality(self.srv, qda, int(q))
            self._set_value(da, value)
        finally:
            L.IedServer_unlockDataModel(self.srv)
        return t_set

    def get(self, ref: str):
        """A leaf's value, or {name: value} for a structure or a whole data object."""
        n = L.IedModel_getModelNodeByObjectReference(self.model, ref.split("[", 1)[0].strip())
        if n is None or n.modelType not in (L.DataAttributeModelType, L.DataObjectModelType):
            raise KeyError(f"no such data object or attribute {ref}")
        L.IedServer_lockDataModel(self.srv)
        try:
            return self._json_of(n)
        finally:
            L.IedServer_unlockDataModel(self.srv)

    def _json_of(self, n):
        if n.modelType == L.DataObjectModelType:
            return {c.name: self._json_of(c) for c in children(n)}
        return to_json(L.toDataAttribute(n))

    def values(self) -> dict:
        out = {}
        L.IedServer_lockDataModel(self.srv)
        try:
            for ld in self.spec["ldevices"]:
                dom = domain_of(self.spec, ld)
                for ln in ld["lns"]:
                    lnn = L.IedModel_getModelNodeByObjectReference(self.model, f"{dom}/{ln_name(ln)}")
                    for path, da in leaves(lnn):
                        fc = FC_NAMES.get(da.fc, str(da.fc))
                        if fc == "CO":
                            continue
                        parts = path.split(".")
                        mms = f"{dom}/{ln_name(ln)}${fc}$" + "$".join(parts)
                        out[f"{dom}/{ln_name(ln)}.{path}"] = {"fc": fc, "mms": mms, "value": to_json(da)}
        finally:
            L.IedServer_unlockDataModel(self.srv)
        return out

    # --- controls ---
    def _action_entry(self, ref, act, ctl_val) -> dict:
        ident = _or_ident(act)
        return {
            "ref": ref,
            "action": "select" if L.ControlAction_isSelect(act) else "operate",
            "ctlVal": ctl_val,
            "orCat": int(L.ControlAction_getOrCat(act)),
            "orIdent": ident.decode("latin-1") if ident is not None else None,
            "orIdent_hex": ident.hex() if ident is not None else None,
            "ctlNum": int(L.ControlAction_getCtlNum(act)),
            "synchro_check": bool(L.ControlAction_getSynchroCheck(act)),
            "T": int(L.ControlAction_getControlTime(act)) / 1000.0,
            "t_received": time.time(),
        }

    def _log(self, entry: dict) -> None:
        with self._lock:
            self.actions.append(entry)

    def _note_synchro(self, ref, synchro) -> None:
        with self._lock:
            for e in reversed(self.actions):
                if e["ref"] == ref and e["action"] == "operate":
                    e["synchro_check"] = synchro
                    break

    def controls(self) -> list:
        with self._lock:
            return list(self.actions)

    # --- lifecycle ---
    def _init_values(self) -> None:
        now = time.time()
        L.IedServer_lockDataModel(self.srv)
        try:
            for ld in self.spec["ldevices"]:
                dom = domain_of(self.spec, ld)
                for ln in ld["lns"]:
                    base_ln = f"{dom}/{ln_name(ln)}"
                    lnn = L.IedModel_getModelNodeByObjectReference(self.model, base_ln)
                    for path, da in leaves(lnn):  # every t: now; every q: good
                        if da.fc == L.IEC61850_FC_CO:
                            continue
                        if da.name == "t" and da.type == L.IEC61850_TIMESTAMP:
                            self._set_ts(da, now)
                        elif da.name == "q" and da.type == L.IEC61850_QUALITY:
                            L.IedServer_updateQuality(self.srv, da, 0)
                    for do in ln["dos"]:
                        init = dict(do.get("init", {}))
                        if "ctl" in do:
                            init["ctlModel"] = CTL[do["ctl"]][1]
                        for path, v in init.items():
                            self._set_value(self.node(f"{base_ln}.{do['name']}.{path}"), v)
        finally:
            L.IedServer_unlockDataModel(self.srv)

    def _install_controls(self) -> None:
        for ld in self.spec["ldevices"]:
            dom = domain_of(self.spec, ld)
            for ln in ld["lns"]:
                for do in ln["dos"]:
                    ctl = do.get("ctl", "status-only")
                    if ctl == "status-only":
                        continue
                    ref = f"{dom}/{ln_name(ln)}.{do['name']}"
                    don = L.toDataObject(L.IedModel_getModelNodeByObjectReference(self.model, ref))
                    L.IedServer_updateCtlModel(self.srv, don, LIB_CTL_MODEL[CTL[ctl][1]])
                    sub = L.ControlSubscriberForPython()
                    sub.setIedServer(self.srv)
                    sub.setControlObject(don)
                    chk, wait, ctlh = _Check(), _Wait(), _Control()
                    for h in (chk, wait, ctlh):
                        h.peer, h.ref, h.cdc = self, ref, do["cdc"]
                    self._handlers += [chk, wait, ctlh]
                    sub.setCheckHandler(chk.__disown__())
                    sub.setWaitHandler(wait.__disown__())
                    sub.setControlHandler(ctlh.__disown__())
                    sub.subscribe()
                    self._subs.append(sub)

    def start(self, host: str, port: int) -> None:
        self.srv = L.IedServer_create(self.model)
        # the TimeQuality of timestamps libiec61850 makes itself: leap seconds known, 10 bits
        L.IedServer_setTimeQuality(self.srv, True, False, False, 10)
        self._init_values()
        self._install_controls()
        L.IedServer_setLocalIpAddress(self.srv, host)
        L.IedServer_start(self.srv, port)
        if not L.IedServer_isRunning(self.srv):
            raise RuntimeError(f"libiec61850 could not listen on {host}:{port}")

    def stop(self) -> None:
        if self.srv is not None:
            L.IedServer_stop(self.srv)
            self.srv = None

    # --- the stdin protocol ---
    def burst(self, ref: str, count: int, rate: float, start=None, step=1.0) -> dict:
        da = self.node(ref)
        cur = self.get(ref) if start is None else start
        first = last = None
        v = cur
        t0 = time.monotonic()
        for i in range(int(count)):
            if da.type == L.IEC61850_BOOLEAN:
                v = not v
            elif da.type == L.IEC61850_CODEDENUM:
                v = 2 if v != 2 else 1
            elif isinstance(v, float) or da.type in (L.IEC61850_FLOAT32, L.IEC61850_FLOAT64):
                v = float(v) + float(step)
            else:
                v = int(v) + int(step)
            ts = self.set(ref, v)
            first = ts if first is None else first
            last = ts
            if rate and rate > 0:
                delay = t0 + (i + 1) / float(rate) - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
        return {"ok": True, "count": int(count), "t_first": first, "t_last": last,
                "last_value": v, "elapsed": time.monotonic() - t0}

    def command(self, cmd: dict) -> dict:
        if not isinstance(cmd, dict):
            return {"error": "a JSON object expected"}
        if "set" in cmd:
            if "value" not in cmd:
                return {"error": "set needs value"}
            return {"ok": True, "t": self.set(str(cmd["set"]), cmd["value"], cmd.get("q"), cmd.get("t"))}
        if "get" in cmd:
            return {"value": self.get(str(cmd["get"]))}
        if "interlock" in cmd:
            self.interlock = bool(cmd["interlock"])
            return {"ok": True, "interlock": self.interlock}
        if "controls" in cmd:
            return {"controls": self.controls()}
        if "burst" in cmd:
            b = cmd["burst"]
            if not isinstance(b, dict) or "ref" not in b:
                return {"error": "burst needs {ref, count, rate}"}
            return self.burst(str(b["ref"]), int(b.get("count", 1)), float(b.get("rate", 0)),
                              b.get("start"), b.get("step", 1.0))
        if "values" in cmd:
            return {"values": self.values()}
        if "quit" in cmd:
            return {"ok": True, "quit": True}
        return {"error": f"unknown command {sorted(cmd)}"}


def serve(spec: dict = DEFAULT_SPEC, host: str = "127.0.0.1", port: int = 102) -> Peer:
    """Build the libiec61850 model from spec and start serving it on host:port."""
    peer = Peer(spec)
    peer.start(host, port)
    return peer


# ---------------------------------------------------------------------------------
# SCL
# ---------------------------------------------------------------------------------

BTYPE = {
    L.IEC61850_BOOLEAN: "BOOLEAN", L.IEC61850_INT8: "INT8", L.IEC61850_INT16: "INT16",
    L.IEC61850_INT32: "INT32", L.IEC61850_INT64: "INT64", L.IEC61850_INT128: "INT128",
    L.IEC61850_INT8U: "INT8U", L.IEC61850_INT16U: "INT16U", L.IEC61850_INT24U: "INT24U",
    L.IEC61850_INT32U: "INT32U", L.IEC61850_FLOAT32: "FLOAT32", L.IEC61850_FLOAT64: "FLOAT64",
    L.IEC61850_ENUMERATED: "Enum", L.IEC61850_OCTET_STRING_64: "Octet64",
    L.IEC61850_OCTET_STRING_6: "Octet6", L.IEC61850_OCTET_STRING_8: "Octet16",
    L.IEC61850_VISIBLE_STRING_32: "VisString32", L.IEC61850_VISIBLE_STRING_64: "VisString64",
    L.IEC61850_VISIBLE_STRING_65: "VisString65", L.IEC61850_VISIBLE_STRING_129: "VisString129",
    L.IEC61850_VISIBLE_STRING_255: "VisString255", L.IEC61850_UNICODE_STRING_255: "Unicode255",
    L.IEC61850_TIMESTAMP: "Timestamp", L.IEC61850_QUALITY: "Quality", L.IEC61850_CHECK: "Check",
    L.IEC61850_CODEDENUM: "Dbpos", L.IEC61850_CONSTRUCTED: "Struct",
    L.IEC61850_ENTRY_TIME: "EntryTime", L.IEC61850_PHYCOMADDR: "PhyComAddr",
    L.IEC61850_CURRENCY: "Currency", L.IEC61850_OPTFLDS: "OptFlds", L.IEC61850_TRGOPS: "TrgOps",
}

MULTIPLIERS = {-24: "y", -21: "z", -18: "a", -15: "f", -12: "p", -9: "n", -6: "µ", -3: "m", -2: "c",
               -1: "d", 0: "", 1: "da", 2: "h", 3: "k", 6: "M", 9: "G", 12: "T", 15: "P", 18: "E",
               21: "Z", 24: "Y"}
SI_UNITS = {1: "", 2: "m", 3: "kg", 4: "s", 5: "A", 6: "K", 7: "mol", 8: "cd", 9: "deg", 10: "rad",
            11: "sr", 21: "Gy", 22: "Bq", 23: "°C", 24: "Sv", 25: "F", 26: "C", 27: "S", 28: "H",
            29: "V", 30: "ohm", 31: "J", 32: "N", 33: "Hz", 34: "lx", 35: "Lm", 36: "Wb", 37: "T",
            38: "W", 39: "Pa", 41: "m²", 42: "m³", 43: "m/s", 44: "m/s²", 45: "m³/s", 46: "m/m³",
            47: "M", 48: "kg/m³", 49: "m²/s", 50: "W/m K", 51: "J/K", 52: "ppm", 53: "1/s",
            54: "rad/s", 61: "VA", 62: "Watts", 63: "VAr", 64: "phi", 65: "cos(phi)", 66: "Vs",
            67: "V²", 68: "As", 69: "A²", 70: "A²t", 71: "VAh", 72: "Wh", 73: "VArh", 74: "V/Hz",
            75: "Hz/s", 76: "char", 77: "char/s", 78: "kgm²", 79: "dB", 80: "J/Wh", 81: "W/s",
            82: "l/s", 83: "dBm"}
ENUMS = {
    "CtlModelKind": {0: "status-only", 1: "direct-with-normal-security", 2: "sbo-with-normal-security",
                     3: "direct-with-enhanced-security", 4: "sbo-with-enhanced-security"},
    "orCategory": {0: "not-supported", 1: "bay-control", 2: "station-control", 3: "remote-control",
                   4: "automatic-bay", 5: "automatic-station", 6: "automatic-remote", 7: "maintenance",
                   8: "process"},
    "BehaviourModeKind": {1: "on", 2: "blocked", 3: "test", 4: "test/blocked", 5: "off"},
    "HealthKind": {1: "Ok", 2: "Warning", 3: "Alarm"},
    "SboClassKind": {0: "operate-once", 1: "operate-many"},
    "MultiplierKind": MULTIPLIERS,
    "SIUnitKind": SI_UNITS,
}


def _enum_type(do_name: str, path: list) -> str:
    last = path[-1]
    if last == "ctlModel":
        return "CtlModelKind"
    if last == "orCat":
        return "orCategory"
    if last == "SIUnit":
        return "SIUnitKind"
    if last == "multiplier":
        return "MultiplierKind"
    if last == "sboClass":
        return "SboClassKind"
    if do_name in ("Beh", "Mod"):
        return "BehaviourModeKind"
    if do_name == "Health":
        return "HealthKind"
    raise ValueError(f"no enum type for {do_name}.{'.'.join(path)}")


_STRUCT_NAMES = {"mag": "AnalogueValue", "cVal": "Vector", "origin": "Originator", "units": "Unit"}
_TRG_ATTRS = [("dchg", L.TRG_OPT_DATA_CHANGED), ("qchg", L.TRG_OPT_QUALITY_CHANGED),
              ("dupd", L.TRG_OPT_DATA_UPDATE)]


class _Templates:
    def __init__(self):
        self.lntypes: dict = {}   # signature -> (id, element)
        self.dotypes: dict = {}
        self.datypes: dict = {}
        self.ids: set = set()
        self.enums_used: set = set()

    def _unique(self, base: str) -> str:
        i, cand = 1, base
        while cand in self.ids:
            i += 1
            cand = f"{base}_{i}"
        self.ids.add(cand)
        return cand

    def _da_attrs(self, da, do_name, path, struct_hint) -> dict:
        a = {"name": da.name}
        bt = BTYPE[da.type]
        a["bType"] = bt
        if bt == "Enum":
            et = _enum_type(do_name, path)
            self.enums_used.add(et)
            a["type"] = et
        elif bt == "Struct":
            a["type"] = self.datype(da, do_name, path, struct_hint)
        if da.elementCount and da.elementCount > 0:
            a["count"] = str(da.elementCount)
        return a

    def datype(self, da, do_name, path, hint) -> str:
        bdas = []
        for c in children(da):
            c = L.toDataAttribute(c)
            bdas.append(self._da_attrs(c, do_name, path + [c.name], hint))
        sig = ("DA", tuple(tuple(sorted(b.items())) for b in bdas))
        if sig in self.datypes:
            return self.datypes[sig][0]
        base = _STRUCT_NAMES.get(da.name) or f"{hint}_{da.name}"
        if da.name in ("Oper", "SBOw", "Cancel"):
            ctl_val = next((b["bType"] for b in bdas if b["name"] == "ctlVal"), "X")
            base = f"{'Cancel' if da.name == 'Cancel' else 'Operate'}_{ctl_val}"
        tid = self._unique(base)
        el = ET.Element("DAType", {"id": tid})
        for b in bdas:
            ET.SubElement(el, "BDA", b)
        self.datypes[sig] = (tid, el)
        return tid

    def dotype(self, do_node, cdc: str, hint: str, sub_cdcs: dict) -> str:
        items = []
        for c in children(do_node):
            if c.modelType == L.DataObjectModelType:
                items.append(("SDO", {"name": c.name, "type": self.dotype(c, sub_cdcs.get(c.name, "CMV"),
                                                                          sub_cdcs.get(c.name, "CMV"), {})}))
            else:
                da = L.toDataAttribute(c)
                a = self._da_attrs(da, do_node.name, [da.name], hint)
                a["fc"] = FC_NAMES[da.fc]
                for key, bit in _TRG_ATTRS:
                    if da.triggerOptions & bit:
                        a[key] = "true"
                items.append(("DA", a))
        sig = (cdc, tuple((k, tuple(sorted(a.items()))) for k, a in items))
        if sig in self.dotypes:
            return self.dotypes[sig][0]
        tid = self._unique(hint)
        el = ET.Element("DOType", {"id": tid, "cdc": cdc})
        for k, a in items:
            ET.SubElement(el, k, a)
        self.dotypes[sig] = (tid, el)
        return tid

    def lntype(self, ln: dict, lnn) -> str:
        dos = []
        by_name = {c.name: c for c in children(lnn)}
        for do in ln["dos"]:
            hint = do.get("type") or _do_type_hint(do)
            sub = {s: "CMV" for s in do.get("sdos", [])}
            dos.append({"name": do["name"], "type": self.dotype(by_name[do["name"]], do["cdc"], hint, sub)})
        sig = (ln["lnClass"], tuple(tuple(sorted(d.items())) for d in dos))
        if sig in self.lntypes:
            return self.lntypes[sig][0]
        tid = self._unique(f"{ln['lnClass']}_T")
        el = ET.Element("LNodeType", {"id": tid, "lnClass": ln["lnClass"]})
        for d in dos:
            ET.SubElement(el, "DO", d)
        self.lntypes[sig] = (tid, el)
        return tid


def _do_type_hint(do: dict) -> str:
    short = {"direct-with-normal-security": "DOns", "sbo-with-normal-security": "SBOns",
             "direct-with-enhanced-security": "DOes", "sbo-with-enhanced-security": "SBOes"}
    if do.get("ctl") in short:
        return f"{do['cdc']}_{short[do['ctl']]}"
    if do["name"] in ("Beh", "Mod", "Health"):
        return f"{do['cdc']}_{do['name']}"
    return do["cdc"]


def _enum_literal(enum_type: str, v: int) -> str:
    return ENUMS[enum_type].get(int(v), str(v))


def _doi(parent, do: dict, lnn, domain_unused=None) -> None:
    init = dict(do.get("init", {}))
    if "ctl" in do:
        init["ctlModel"] = CTL[do["ctl"]][1]
    if not init:
        return
    doi = ET.SubElement(parent, "DOI", {"name": do["name"]})
    do_node = next(c for c in children(lnn) if c.name == do["name"])
    for path, v in init.items():
        parts = path.split(".")
        el, node = doi, do_node
        for p in parts[:-1]:
            node = next(c for c in children(node) if c.name == p)
            found = next((e for e in el.findall("SDI") if e.get("name") == p), None)
            el = found if found is not None else ET.SubElement(el, "SDI", {"name": p})
        node = L.toDataAttribute(next(c for c in children(node) if c.name == parts[-1]))
        dai = ET.SubElement(el, "DAI", {"name": parts[-1]})
        if node.type == L.IEC61850_ENUMERATED:
            text = _enum_literal(_enum_type(do["name"], parts), v)
        elif node.type == L.IEC61850_CODEDENUM:
            text = {0: "intermediate-state", 1: "off", 2: "on", 3: "bad-state"}[int(v)]
        elif isinstance(v, bool):
            text = "true" if v else "false"
        else:
            text = str(v)
        ET.SubElement(dai, "Val").text = text


def _split_member(member: str) -> dict:
    parts = member.split("$")
    ln, fc, names = parts[0], parts[1], parts[2:]
    return {"ln": ln, "fc": fc, "names": names}


def scl_tree(spec: dict) -> ET.ElementTree:
    """The SCL document (an ElementTree, default namespace) for spec."""
    ns = "http://www.iec.ch/61850/2003/SCL"
    model = build_model(spec)
    scl = ET.Element("SCL", {"xmlns": ns, "version": "2007", "revision": "B"})
    ET.SubElement(scl, "Header", {"id": f"gridscada-{spec['ied']}", "version": "1", "revision": "A",
                                  "toolID": "gridscada tests/e2e/iec61850_peer.py",
                                  "nameStructure": "IEDName"})
    comm = ET.SubElement(scl, "Communication")
    sn = ET.SubElement(comm, "SubNetwork", {"name": spec.get("subnetwork", "StationBus"), "type": "8-MMS"})
    cap = ET.SubElement(sn, "ConnectedAP", {"iedName": spec["ied"], "apName": spec.get("ap", "AP1")})
    addr = ET.SubElement(cap, "Address")
    for ptype, val in (("IP", spec.get("host", "127.0.0.1")), ("IP-SUBNET", "255.255.255.0"),
                       ("IP-GATEWAY", "0.0.0.0"), ("OSI-AP-Title", "1,1,9999,1"),
                       ("OSI-AE-Qualifier", "12"), ("OSI-PSEL", "00000001"), ("OSI-SSEL", "0001"),
                       ("OSI-TSEL", "0001"), ("MMS-Port", str(spec.get("port", 102)))):
        ET.SubElement(addr, "P", {"type": ptype}).text = val
    ied = ET.SubElement(scl, "IED", {"name": spec["ied"], "manufacturer": spec.get("manufacturer", "gridscada"),
                                     "type": spec.get("ied_type", "TestIED"),
                                     "configVersion": spec.get("config_version", "1.0"),
                                     "originalSclVersion": "2007", "originalSclRevision": "B"})
    services = ET.SubElement(ied, "Services")
    for s in ("DynAssociation", "GetDirectory", "GetDataObjectDefinition", "DataObjectDirectory",
              "GetDataSetValue", "DataSetDirectory", "ReadWrite"):
        ET.SubElement(services, s)
    ET.SubElement(services, "ConfReportControl", {"max": "10"})
    ET.SubElement(services, "GetCBValues")
    ET.SubElement(services, "ReportSettings", {"cbName": "Conf", "datSet": "Conf", "rptID": "Dyn",
                                               "optFields": "Dyn", "bufTime": "Dyn", "trgOps": "Dyn",
                                               "intgPd": "Dyn"})
    ap = ET.SubElement(ied, "AccessPoint", {"name": spec.get("ap", "AP1")})
    server = ET.SubElement(ap, "Server")
    ET.SubElement(server, "Authentication", {"none": "true"})
    tpl = _Templates()
    for ld in spec["ldevices"]:
        dom = domain_of(spec, ld)
        ldel = ET.SubElement(server, "LDevice", {"inst": ld["inst"]})
        by_name = {ln_name(ln): ln for ln in ld["lns"]}
        for ln in ld["lns"]:
            lnn = L.IedModel_getModelNodeByObjectReference(model, f"{dom}/{ln_name(ln)}")
            lntype = tpl.lntype(ln, lnn)
            if ln["lnClass"] == "LLN0":
                lnel = ET.SubElement(ldel, "LN0", {"lnClass": "LLN0", "inst": "", "lnType": lntype})
            else:
                lnel = ET.SubElement(ldel, "LN", {"prefix": ln.get("prefix", ""), "lnClass": ln["lnClass"],
                                                  "inst": ln["inst"], "lnType": lntype})
            for ds in ln.get("datasets", []):
                dsel = ET.SubElement(lnel, "DataSet", {"name": ds["name"]})
                for member in ds["members"]:
                    m = _split_member(member)
                    target = by_name[m["ln"]]
                    top = next(d for d in target["dos"] if d["name"] == m["names"][0])
                    n_do = 2 if top.get("sdos") and len(m["names"]) > 1 and m["names"][1] in top["sdos"] else 1
                    fcda = {"ldInst": ld["inst"], "prefix": target.get("prefix", ""),
                            "lnClass": target["lnClass"], "lnInst": target.get("inst", ""),
                            "doName": ".".join(m["names"][:n_do])}
                    if len(m["names"]) > n_do:
                        fcda["daName"] = ".".join(m["names"][n_do:])
                    fcda["fc"] = m["fc"]
                    ET.SubElement(dsel, "FCDA", fcda)
            for rc in ln.get("rcbs", []):
                rcel = ET.SubElement(lnel, "ReportControl", {
                    "name": rc["name"], "datSet": rc["datSet"], "intgPd": str(rc["intgPd"]),
                    "rptID": rc["rptID"], "confRev": str(rc["confRev"]),
                    "buffered": "true" if rc["buffered"] else "false", "bufTime": str(rc["bufTime"]),
                    "indexed": "false"})
                ET.SubElement(rcel, "TrgOps", {k: ("true" if k in rc["trgOps"] else "false")
                                               for k in ("dchg", "qchg", "dupd", "period", "gi")})
                ET.SubElement(rcel, "OptFields", {k: ("true" if k in rc["optFields"] else "false")
                                                  for k in ("seqNum", "timeStamp", "dataSet", "reasonCode",
                                                            "dataRef", "entryID", "configRef", "bufOvfl")})
                ET.SubElement(rcel, "RptEnabled", {"max": "1"})
            for do in ln["dos"]:
                _doi(lnel, do, lnn)
    dtt = ET.SubElement(scl, "DataTypeTemplates")
    for group in (tpl.lntypes, tpl.dotypes, tpl.datypes):
        for tid, el in group.values():
            dtt.append(el)
    for et in sorted(tpl.enums_used):
        el = ET.SubElement(dtt, "EnumType", {"id": et})
        for ord_, text in sorted(ENUMS[et].items()):
            ev = ET.SubElement(el, "EnumVal", {"ord": str(ord_)})
            ev.text = text
    ET.indent(scl, space="  ")
    return ET.ElementTree(scl)


def write_scl(spec: dict, path: str) -> None:
    """Write the IEC 61850-6 ed.2 (2007B) SCL of spec's model to path."""
    tree = scl_tree(spec)
    with open(path, "wb") as f:
        tree.write(f, encoding="UTF-8", xml_declaration=True)
        f.write(b"\n")


def scl_drift(path: str, host: str, port: int, domain: str = "TESTLD0") -> dict:
    """Compare the SCL at path, as open61850's SCL loader reads it, with what a running
    server announces (GetNameList of domain's variables, read by open61850's client).
    Empty lists = no drift. libiec61850 spells the BRCB attribute ``TimeofEntry``
    where open61850 builds ``TimeOfEntry``; that one name is normalised."""
    from open61850.mms import MmsClient
    from open61850.server.model import IedModel

    def norm(names):
        return {n.replace("$TimeofEntry", "$TimeOfEntry") for n in names}

    scl = norm(IedModel.from_scl(path).names(domain))
    with MmsClient.connect(host, port) as c:
        srv = norm(c.get_name_list(0, domain))
    return {"only_in_scl": sorted(scl - srv), "only_in_server": sorted(srv - scl), "names": len(srv)}


# ---------------------------------------------------------------------------------
# Script mode
# ---------------------------------------------------------------------------------

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--scl", help="write the SCL of the model here first")
    ap.add_argument("--ied", default=DEFAULT_SPEC["ied"], help="IED name (domain = IED name + LD inst)")
    args = ap.parse_args(argv)

    # Only our JSON goes to the real stdout; C printf (the binding's trace lines) goes to stderr.
    sys.stdout.flush()
    out_fd = os.dup(1)
    os.dup2(2, 1)
    out = os.fdopen(out_fd, "w", buffering=1)
    sys.stdout = sys.stderr

    def emit(obj) -> None:
        out.write(json.dumps(obj, separators=(",", ":")) + "\n")
        out.flush()

    spec = with_ied(DEFAULT_SPEC, args.ied)
    spec["host"], spec["port"] = args.host, args.port
    if args.scl:
        write_scl(spec, args.scl)
    peer = serve(spec, args.host, args.port)
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(SystemExit(0)))
    emit({"ready": True, "port": args.port})
    try:
        for line in sys.stdin:
            line = line.strip()
            if not line:
                continue
            try:
                cmd = json.loads(line)
            except ValueError as e:
                emit({"error": f"bad JSON: {e}"})
                continue
            try:
                ans = peer.command(cmd)
            except Exception as e:
                ans = {"error": f"{type(e).__name__}: {e}"}
            emit(ans)
            if ans.get("quit"):
                break
    except (KeyboardInterrupt, SystemExit):
        pass
    finally:
        peer.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
