"""The catalog: an index of every session, model, table, push, verification, rollback and
report (identity, time, outcome, key figures, file path and sha256), in SQLite by default
(<recordings_dir>/catalog.sqlite) and forwarded to a shared PostgreSQL when `[catalog] url`
names one. The files stay the records: the index can be rebuilt from them at any time.

- models.py   the tables (SQLAlchemy 2); migrations/ their Alembic revisions
- db.py       opening a catalog: engines, migration, refusal of a newer schema
- identity_reader.py tolerant reading of the identity a file carries
- readers.py  a file's (or audit entry's) record
- store.py    the local catalog, its backlog and forwarding to the shared one
- files.py    scanning folders: index, rebuild, check
- writer.py   the runner sink and `register` for the jobs
- history.py  a leg's history, the list of legs, due dates and drift
- fleet.py    the completed sessions of a leg type (the diagnosis' `--twin fleet:TYPE`)
"""
