#!/usr/bin/env python3
"""A simulated Sparkplug B edge node (paho-mqtt + protobuf with the Eclipse
Tahu payload), independent of gridscada's Rust code: the peer of the
central host's end-to-end test (tests/e2e/sparkplug_central.sh).

    sparkplug_edge_sim.py run --broker 127.0.0.1:1883 --group Grid --node site-a
    sparkplug_edge_sim.py bad --broker 127.0.0.1:1883 --group Grid --node site-a

`run`: NDEATH as the MQTT will (bdSeq), NBIRTH with a node metric, one
DBIRTH for device PV1 (a measured power, a writable setpoint, a running
flag), DDATA of the power every --period seconds, a rebirth on NCMD
"Node Control/Rebirth", and a DCMD to the setpoint applied and reported in
DDATA after --confirm-delay seconds (never with --ignore-writes). Every
command received is printed as one JSON line on stdout.

`bad`: publishes, as this node, a payload that is no protobuf, a DDATA with
an alias no birth declared, and a message of --oversize bytes.
"""

import argparse
import json
import sys
import threading
import time

import paho.mqtt.client as mqtt
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

# --- The Tahu payload (sparkplug_b.proto), declared here --------------------
F = descriptor_pb2.FieldDescriptorProto
TYPES = {
    "uint64": F.TYPE_UINT64, "uint32": F.TYPE_UINT32, "string": F.TYPE_STRING,
    "bool": F.TYPE_BOOL, "bytes": F.TYPE_BYTES, "float": F.TYPE_FLOAT,
    "double": F.TYPE_DOUBLE,
}


def _message(fdp, name, fields, oneof=None):
    m = fdp.message_type.add(name=name)
    if oneof:
        m.oneof_decl.add(name=oneof[0])
    for num, fname, ftype, *rest in fields:
        f = m.field.add(name=fname, number=num)
        f.label = F.LABEL_REPEATED if "repeated" in rest else F.LABEL_OPTIONAL
        if ftype in TYPES:
            f.type = TYPES[ftype]
        else:
            f.type = F.TYPE_MESSAGE
            f.type_name = ".org.eclipse.tahu.protobuf." + ftype
        if oneof and fname in oneof[1]:
            f.oneof_index = 0


def _payload_class():
    fdp = descriptor_pb2.FileDescriptorProto(
        name="sparkplug_b_sim.proto", package="org.eclipse.tahu.protobuf", syntax="proto2")
    _message(fdp, "PropertyValue", [
        (1, "type", "uint32"), (2, "is_null", "bool"), (3, "int_value", "uint32"),
        (4, "long_value", "uint64"), (5, "float_value", "float"), (6, "double_value", "double"),
        (7, "boolean_value", "bool"), (8, "string_value", "string"),
    ], oneof=("value", {"int_value", "long_value", "float_value", "double_value",
                        "boolean_value", "string_value"}))
    _message(fdp, "PropertySet", [(1, "keys", "string", "repeated"),
                                  (2, "values", "PropertyValue", "repeated")])
    _message(fdp, "Metric", [
        (1, "name", "string"), (2, "alias", "uint64"), (3, "timestamp", "uint64"),
        (4, "datatype", "uint32"), (5, "is_historical", "bool"), (6, "is_transient", "bool"),
        (7, "is_null", "bool"), (9, "properties", "PropertySet"),
        (10, "int_value", "uint32"), (11, "long_value", "uint64"), (12, "float_value", "float"),
        (13, "double_value", "double"), (14, "boolean_value", "bool"),
        (15, "string_value", "string"), (16, "bytes_value", "bytes"),
    ], oneof=("value", {"int_value", "long_value", "float_value", "double_value",
                        "boolean_value", "string_value", "bytes_value"}))
    _message(fdp, "Payload", [
        (1, "timestamp", "uint64"), (2, "metrics", "Metric", "repeated"), (3, "seq", "uint64"),
        (4, "uuid", "string"), (5, "body", "bytes"),
    ])
    pool = descriptor_pool.DescriptorPool()
    pool.Add(fdp)
    return message_factory.GetMessageClass(
        pool.FindMessageTypeByName("org.eclipse.tahu.protobuf.Payload"))


Payload = _payload_class()
INT64, DOUBLE, BOOLEAN, STRING = 4, 10, 11, 12
VALUE_FIELD = {INT64: "long_value", DOUBLE: "double_value", BOOLEAN: "boolean_value",
               STRING: "string_value"}


def now_ms():
    return int(time.time() * 1000)


def add_metric(p, name=None, alias=None, datatype=None, value=None, props=None):
    m = p.metrics.add()
    if name is not None:
        m.name = name
    if alias is not None:
        m.alias = alias
    m.timestamp = now_ms()
    if datatype is not None:
        m.datatype = datatype
        if value is not None:
            setattr(m, VALUE_FIELD[datatype], value)
    for key, (ptype, pvalue) in (props or {}).items():
        m.properties.keys.append(key)
        pv = m.properties.values.add()
        pv.type = ptype
        setattr(pv, VALUE_FIELD[ptype], pvalue)
    return m


def metric_value(m):
    which = m.WhichOneof("value")
    return getattr(m, which) if which else None


class Edge:
    """One edge node with one device, PV1."""

    def __init__(self, args):
        self.args = args
        self.g, self.node = args.group, args.node
        self.bd_seq = args.bdseq
        self.seq = 0
        self.lock = threading.Lock()
        self.power = 100.0
        self.setpoint = 50.0
        self.running = True
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2,
                                  client_id=f"edge-sim-{self.node}", clean_session=True)
        death = Payload(timestamp=now_ms())
        add_metric(death, "bdSeq", None, INT64, self.bd_seq)
        self.client.will_set(self.topic("NDEATH"), death.SerializeToString(), qos=1, retain=False)
        self.client.on_connect = self.on_connect
        self.client.on_message = self.on_message

    def topic(self, kind, device=None):
        t = f"spBv1.0/{self.g}/{kind}/{self.node}"
        return f"{t}/{device}" if device else t

    def next_seq(self):
        s = self.seq
        self.seq = (self.seq + 1) % 256
        return s

    def publish(self, kind, payload, device=None):
        self.client.publish(self.topic(kind, device), payload.SerializeToString(), qos=0)

    def births(self):
        with self.lock:
            self.seq = 0
            nb = Payload(timestamp=now_ms(), seq=self.next_seq())
            add_metric(nb, "bdSeq", None, INT64, self.bd_seq)
            add_metric(nb, "Node Control/Rebirth", None, BOOLEAN, False)
            add_metric(nb, "Feeder/Volts", 1, DOUBLE, 230.0 + self.args.index,
                       {"engUnit": (STRING, "V")})
            self.publish("NBIRTH", nb)
            db = Payload(timestamp=now_ms(), seq=self.next_seq())
            add_metric(db, "P", 2, DOUBLE, self.power, {"engUnit": (STRING, "kW")})
            add_metric(db, "P_set", 3, DOUBLE, self.setpoint,
                       {"engUnit": (STRING, "kW"), "writable": (BOOLEAN, True)})
            add_metric(db, "Running", 4, BOOLEAN, self.running)
            self.publish("DBIRTH", db, "PV1")

    def on_connect(self, client, userdata, flags, reason_code, properties):
        client.subscribe(self.topic("NCMD"), qos=1)
        client.subscribe(self.topic("DCMD", "+"), qos=1)
        self.births()
        print(json.dumps({"event": "born", "node": self.node}), flush=True)

    def on_message(self, client, userdata, msg):
        p = Payload()
        try:
            p.ParseFromString(msg.payload)
        except Exception as e:  # a broken command is reported, not fatal
            print(json.dumps({"event": "bad_command", "error": str(e)}), flush=True)
            return
        kind = msg.topic.split("/")[2]
        for m in p.metrics:
            print(json.dumps({"event": kind, "node": self.node, "topic": msg.topic,
                              "name": m.name, "alias": m.alias, "value": metric_value(m)}),
                  flush=True)
            if kind == "NCMD" and m.name == "Node Control/Rebirth" and metric_value(m):
                self.births()
            elif kind == "DCMD" and (m.name == "P_set" or m.alias == 3):
                if not self.args.ignore_writes:
                    threading.Timer(self.args.confirm_delay, self.take_setpoint,
                                    [float(metric_value(m))]).start()

    def take_setpoint(self, value):
        with self.lock:
            self.setpoint = value
            d = Payload(timestamp=now_ms(), seq=self.next_seq())
            add_metric(d, None, 3, None)
            d.metrics[0].double_value = value
            self.publish("DDATA", d, "PV1")

    def tick(self):
        with self.lock:
            self.power = 100.0 + (time.time() % 10)
            d = Payload(timestamp=now_ms(), seq=self.next_seq())
            m = add_metric(d, None, 2, None)
            m.double_value = self.power
            self.publish("DDATA", d, "PV1")

    def run(self):
        host, port = self.args.broker.rsplit(":", 1)
        self.client.connect(host, int(port), keepalive=self.args.keepalive)
        self.client.loop_start()
        try:
            while True:
                time.sleep(self.args.period)
                if self.client.is_connected():
                    self.tick()
        except KeyboardInterrupt:
            pass


def bad(args):
    """Bad input, published as the node: each must be counted and change nothing."""
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"bad-{args.node}")
    host, port = args.broker.rsplit(":", 1)
    c.connect(host, int(port))
    c.loop_start()
    base = f"spBv1.0/{args.group}"
    infos = [c.publish(f"{base}/DDATA/{args.node}/PV1", b"\xff\xff\xff not protobuf", qos=1)]
    p = Payload(timestamp=now_ms(), seq=args.seq)
    m = add_metric(p, None, 4242, None)
    m.double_value = 1.0
    infos.append(c.publish(f"{base}/DDATA/{args.node}/PV1", p.SerializeToString(), qos=1))
    infos.append(c.publish(f"{base}/DDATA/{args.node}/PV1", b"\0" * args.oversize, qos=1))
    for i in infos:
        i.wait_for_publish(10)
    c.loop_stop()
    c.disconnect()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["run", "bad"])
    ap.add_argument("--broker", required=True, help="host:port")
    ap.add_argument("--group", required=True)
    ap.add_argument("--node", required=True)
    ap.add_argument("--index", type=int, default=0, help="makes this site's values its own")
    ap.add_argument("--bdseq", type=int, default=0)
    ap.add_argument("--period", type=float, default=0.5)
    ap.add_argument("--keepalive", type=int, default=2)
    ap.add_argument("--confirm-delay", type=float, default=0.3)
    ap.add_argument("--ignore-writes", action="store_true")
    ap.add_argument("--seq", type=int, default=0, help="bad: the seq of the unknown-alias DDATA")
    ap.add_argument("--oversize", type=int, default=2 * 1024 * 1024)
    args = ap.parse_args()
    if args.mode == "bad":
        bad(args)
    else:
        Edge(args).run()


if __name__ == "__main__":
    sys.exit(main())
