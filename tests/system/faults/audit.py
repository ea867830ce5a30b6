"""Audit triggers: every chunk row written (insert or update of
terrane_chunks) leaves a row in fault_audit, in the writing transaction (so
only committed writes are recorded): the chunk, its revision, the writer (the
connection's client address: each server has its own), the transaction, the
time by the database's clock, and the region's lease as that transaction saw
it: owner, epoch, expiry, and whether this very transaction moved the lease's
write sequence (the fence of save_fenced: its UPDATE of the lease row)."""

SQL = r"""
CREATE TABLE IF NOT EXISTS fault_audit (
  id bigserial PRIMARY KEY,
  at timestamptz NOT NULL DEFAULT clock_timestamp(),
  txid bigint NOT NULL,
  client text,
  x integer NOT NULL, y integer NOT NULL, z integer NOT NULL,
  revision bigint NOT NULL,
  rx integer NOT NULL, ry integer NOT NULL, rz integer NOT NULL,
  owner integer, epoch bigint, expires_at timestamptz,
  fenced boolean NOT NULL);

CREATE OR REPLACE FUNCTION fault_audit_chunk() RETURNS trigger AS $$
DECLARE
  l record;
  v_rx integer := floor(NEW.x / 8.0);
  v_ry integer := floor(NEW.y / 8.0);
  v_rz integer := floor(NEW.z / 8.0);
BEGIN
  SELECT t.owner, t.epoch, t.expires_at,
         (t.xmin::text::bigint = txid_current() % 4294967296) AS mine
    INTO l FROM terrane_leases t WHERE t.rx = v_rx AND t.ry = v_ry AND t.rz = v_rz;
  INSERT INTO fault_audit (txid, client, x, y, z, revision, rx, ry, rz, owner, epoch, expires_at, fenced)
  VALUES (txid_current(), host(inet_client_addr()), NEW.x, NEW.y, NEW.z, NEW.revision, v_rx, v_ry, v_rz,
          l.owner, l.epoch, l.expires_at, COALESCE(l.mine, false));
  RETURN NEW;
END $$ LANGUAGE plpgsql;

DROP TRIGGER IF EXISTS fault_audit_chunk ON terrane_chunks;
CREATE TRIGGER fault_audit_chunk AFTER INSERT OR UPDATE ON terrane_chunks
  FOR EACH ROW EXECUTE FUNCTION fault_audit_chunk();
"""


def install(cluster):
    cluster.psql_script(SQL)


def server_of(client, cluster):
    """The server id of a writer's address (10.213.i.2), else None (a tool from the root namespace)."""
    for s in cluster.servers:
        if client == s.host:
            return s.id
    return None


def check(cluster):
    """The audit's findings: chunk writes outside a lease their writer held
    (not fenced in their own transaction, or the lease another server's), and
    revisions of a chunk written by two servers (or twice)."""
    rows = cluster.psql("SELECT id, extract(epoch FROM at), txid, client, x, y, z, revision, owner, epoch, "
                        "extract(epoch FROM expires_at), fenced FROM fault_audit ORDER BY id")
    outside, late, by_rev = [], 0, {}
    for (i, at, txid, client, x, y, z, rev, owner, epoch, exp, fenced) in rows:
        writer = server_of(client, cluster)
        ok = fenced == "t" and owner != "" and writer is not None and int(owner) == writer
        if not ok:
            outside.append(dict(id=int(i), writer=writer, client=client, chunk=(int(x), int(y), int(z)),
                                revision=int(rev), owner=owner, epoch=epoch, fenced=fenced))
        elif exp and float(exp) < float(at):
            late += 1  # written under the lease row's lock after its expiry: safe, noted
        by_rev.setdefault((int(x), int(y), int(z), int(rev)), []).append((writer, int(txid)))
    double_servers = [dict(chunk=k[:3], revision=k[3], writers=v) for k, v in by_rev.items()
                      if len({w for w, _ in v}) > 1]
    rewritten = sum(1 for v in by_rev.values() if len(v) > 1 and len({w for w, _ in v}) == 1)
    return dict(writes=len(rows), outside=outside, late=late, double_servers=double_servers,
                rewritten=rewritten)
