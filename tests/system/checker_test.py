#!/usr/bin/env python3
"""The fault suite's checker against made-up histories (no cluster, no root):
each finding it must make, and none where there is nothing to find.
    python3 tests/system/checker_test.py"""
import os
import sys
import unittest

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from faults.checker import Write, check, decode_rle  # noqa: E402

A, B = (-1, 100, 1), (0, 100, 1)


def w(i, worker, reg, value, start, end, outcome, edit=None):
    return Write(id=i, edit=edit if edit is not None else i, player="p%d" % worker, worker=worker, reg=reg,
                 value=value, server=1, start=start, end=end, outcome=outcome)


def log(*entries):
    return [dict(id=k, player="", reg=reg, value=v, tick=0) for k, (reg, v) in enumerate(entries)]


class CheckerTest(unittest.TestCase):
    def test_byte_rle_runs_and_occupancy(self):
        self.assertEqual(decode_rle("4411", 1), [(4, 17)])
        self.assertEqual(decode_rle("c264 02".replace(" ", ""), 3), [(2, 100)] * 3)
        self.assertEqual(decode_rle("0605", 2), [(6, 255), (5, 255)])

    def test_a_clean_history_has_no_findings(self):
        ws = [w(0, 0, A, (1, 1), 0, 1, "acked"), w(1, 1, A, (1, 2), 2, 3, "acked"), w(2, 0, A, (1, 3), 4, 5, "unknown")]
        r = check(ws, log((A, (1, 1)), (A, (1, 2))), {A: (1, 2)}, [A])
        self.assertEqual((r["acked"], r["unknown"], r["lost"], r["double"], r["out_of_order"]), (2, 1, 0, 0, 0))

    def test_an_acknowledged_write_missing_from_the_log_is_lost(self):
        ws = [w(0, 0, A, (1, 1), 0, 1, "acked"), w(1, 0, A, (1, 2), 2, 3, "acked")]
        r = check(ws, log((A, (1, 1))), {A: (1, 1)}, [A])
        self.assertEqual(r["lost"], 1)

    def test_rows_that_disagree_with_the_log_count_as_lost(self):
        ws = [w(0, 0, A, (1, 1), 0, 1, "acked")]
        r = check(ws, log((A, (1, 1))), {A: (0, 0)}, [A])
        self.assertEqual(r["lost"], 1)

    def test_a_write_logged_twice_is_double_written(self):
        ws = [w(0, 0, A, (1, 1), 0, 1, "acked")]
        r = check(ws, log((A, (1, 1)), (A, (1, 1))), {A: (1, 1)}, [A])
        self.assertEqual(r["double"], 1)

    def test_a_delayed_forward_applied_after_the_players_later_ack_is_out_of_order(self):
        # p0's first write timed out (forwarded, "may still be applied"); its
        # next, through the other server, was acknowledged; then the first
        # was applied over it.
        ws = [w(0, 0, A, (1, 1), 0, 5, "unknown"), w(1, 0, A, (1, 2), 6, 7, "acked")]
        r = check(ws, log((A, (1, 2)), (A, (1, 1))), {A: (1, 1)}, [A])
        self.assertEqual((r["lost"], r["out_of_order"]), (0, 1))

    def test_a_stale_copy_after_a_later_players_write_is_out_of_order(self):
        ws = [w(0, 0, A, (1, 1), 0, 1, "acked"), w(1, 1, A, (1, 2), 2, 3, "acked")]
        r = check(ws, log((A, (1, 1)), (A, (1, 2)), (A, (1, 1))), {A: (1, 1)}, [A])
        self.assertEqual((r["double"], r["out_of_order"]), (1, 1))

    def test_a_refused_write_in_the_log_is_counted(self):
        ws = [w(0, 0, A, (1, 1), 0, 1, "refused")]
        r = check(ws, log((A, (1, 1))), {A: (1, 1)}, [A])
        self.assertEqual(r["refused_applied"], 1)

    def test_an_edit_across_the_border_is_one_outcome_two_registers(self):
        ws = [w(0, 0, A, (1, 1), 0, 1, "acked", edit=7), w(1, 0, B, (1, 1), 0, 1, "acked", edit=7)]
        r = check(ws, log((A, (1, 1)), (B, (1, 1))), {A: (1, 1), B: (1, 1)}, [A, B])
        self.assertEqual((r["acked"], r["lost"], r["out_of_order"]), (1, 0, 0))


if __name__ == "__main__":
    unittest.main()
