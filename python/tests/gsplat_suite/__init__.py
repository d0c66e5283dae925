"""gsplat 1.5.3's own tests run through verisplat (conftest.py here)."""
