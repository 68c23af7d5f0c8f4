"""Closed-loop subspace identification: IEM and PO-MOESP."""
