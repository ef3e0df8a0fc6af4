"""Shipped default mapping files, one per supported kind of control box."""
