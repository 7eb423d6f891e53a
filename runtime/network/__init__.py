"""Networking: CKMultiPeer (§3.1.4) and a Zenoh transport behind one publish/subscribe interface."""
