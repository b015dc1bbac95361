#!/usr/bin/python3
"""Writes a rosbag2 SQLite bag (OUT/NAME_0.db3 and OUT/metadata.yaml) from JSON lines on stdin, one message
each: {"topic", "type", "log_time_ns", "data" (base64 CDR)}. Python's own sqlite3 module and the rosbag2 schema
(tables topics and messages); called by write_bag.mjs."""
import base64
import json
import os
import sqlite3
import sys

out = sys.argv[1]
name = os.path.basename(os.path.normpath(out))
db_name = f"{name}_0.db3"
db = sqlite3.connect(os.path.join(out, db_name))
db.executescript("""
CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, serialization_format TEXT NOT NULL,
                    offered_qos_profiles TEXT NOT NULL);
CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB NOT NULL);
CREATE INDEX timestamp_idx ON messages (timestamp ASC);
""")
topics = {}
count = 0
for line in sys.stdin:
    if not line.strip():
        continue
    m = json.loads(line)
    if m["topic"] not in topics:
        topics[m["topic"]] = len(topics) + 1
        db.execute("INSERT INTO topics VALUES (?, ?, ?, 'cdr', '')", (topics[m["topic"]], m["topic"], m["type"]))
    db.execute("INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
               (topics[m["topic"]], int(m["log_time_ns"]), base64.b64decode(m["data"])))
    count += 1
db.commit()
db.close()
with open(os.path.join(out, "metadata.yaml"), "w") as f:
    f.write(f"""rosbag2_bagfile_information:
  version: 5
  storage_identifier: sqlite3
  relative_file_paths:
    - {db_name}
  message_count: {count}
""")
